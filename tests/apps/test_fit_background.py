"""``eigview fit --background`` on objects rendered on the textured backdrop: the record, the
seed masks handed to synthesis, evaluate / predict (--model and --onnx) applying it, and
the bad inputs of masks and background colours."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pytest
import skimage.io
import torch

import torch_eigview.scale.galleries
from torch_eigview.apps.view_options import background_arg
from torch_eigview.datasets import Backdrop, OrthographicCamera, make_object, render
from torch_eigview.io.checkpoint import load_recognizer
from torch_eigview.io.preprocessing import Preprocessing

from tests.helpers import run_cli

SIDE = 32
AZIMUTHS = list(range(-20, 21, 10))


def _u8(image: np.ndarray) -> np.ndarray:
    return np.round(image * 255).astype(np.uint8)


@pytest.fixture(scope="module")
def views(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two objects on the backdrop (object well inside the frame), RGB PNGs with mask PNGs."""
    root = tmp_path_factory.mktemp("backdrop")
    camera = OrthographicCamera(SIDE, scale=0.3 * SIDE)
    rows = ["path,object,azimuth,mask"]
    for name in ("egg", "head"):
        for az in AZIMUTHS:
            r = render(make_object(name, seed=1), az, camera, backdrop=Backdrop())
            rgb = _u8(r.image.permute(1, 2, 0).numpy())
            skimage.io.imsave(root / f"{name}{az}.png", rgb, check_contrast=False)
            skimage.io.imsave(
                root / f"{name}{az}_m.png", _u8(r.mask.numpy().astype(float)), check_contrast=False
            )
            rgba = np.dstack([rgb, np.where(r.mask.numpy(), 255, 0).astype(np.uint8)])
            skimage.io.imsave(root / f"{name}{az}_a.png", rgba, check_contrast=False)
            rows.append(f"{name}{az}.png,{name},{az},{name}{az}_m.png")
    (root / "views.csv").write_text("\n".join(rows) + "\n")
    (root / "nomask.csv").write_text("\n".join(r.rsplit(",", 1)[0] for r in rows) + "\n")
    return root


def _fit(views: Path, manifest: str, out: Path, *extra: str) -> list[str]:
    return [
        "fit", "--manifest", str(views / manifest), "--seeds", "0", "10", "--synth", "-20", "20", "2",
        "--elevation", "0", "--extent", "off", "--channels", "1", "-k", "8", "--quiet", *extra, "--out", str(out),
    ]  # fmt: skip


def test_fit_hands_the_seed_masks_to_synthesis_and_records_the_background(
    views: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    seen: list[torch.Tensor | None] = []
    real = torch_eigview.scale.galleries.synthesize_views

    def spy(*args: object, masks: torch.Tensor | None = None, **kwargs: object) -> object:
        seen.append(masks)
        return real(*args, masks=masks, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(torch_eigview.scale.galleries, "synthesize_views", spy)
    out = tmp_path / "m.pt"
    code, _, err = run_cli(_fit(views, "views.csv", out, "--background", "auto"), capsys)
    assert code == 0, err
    _, meta = load_recognizer(out)
    assert Preprocessing.from_json(meta["preprocessing"]) == Preprocessing((SIDE, SIDE), 1, background="auto")
    assert len(seen) == 2 and all(m is not None for m in seen)
    for name in ("egg", "head"):  # objects run in threads: in either order
        want = np.stack([skimage.io.imread(views / f"{name}{a}_m.png") > 0 for a in (0, 10)])
        assert sum(np.array_equal(m.numpy(), want) for m in seen if m is not None) == 1, name
    seen.clear()
    code, out, err = run_cli(_fit(views, "views.csv", tmp_path / "k.pt", "--background", "keep"), capsys)
    assert code == 0 and seen == [None, None], err  # keep, chosen: the threshold
    assert "background keep (as given)" in out
    seen.clear()
    code, out, err = run_cli(_fit(views, "views.csv", tmp_path / "d.pt"), capsys)  # the default
    assert code == 0 and len(seen) == 2 and all(m is not None for m in seen), err
    assert "background auto (the manifest lists masks)" in out
    _, meta = load_recognizer(tmp_path / "d.pt")
    assert Preprocessing.from_json(meta["preprocessing"]).background == "auto"


@pytest.mark.slow
@pytest.mark.parametrize("manifest", ["views.csv", "nomask.csv"])
def test_evaluate_and_predict_apply_the_recorded_background(
    views: Path, manifest: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    model = tmp_path / "m.pt"
    assert run_cli(_fit(views, manifest, model, "--background", "auto"), capsys)[0] == 0
    report = tmp_path / "r.json"
    code, _, err = run_cli(
        ["evaluate", "--model", str(model), "--manifest", str(views / manifest), "--json", str(report)],
        capsys,
    )
    assert code == 0, err
    assert json.loads(report.read_text())["accuracy"] >= 80.0  # two objects: chance is 50
    images = [str(views / f"{n}{a}_a.png") for n in ("egg", "head") for a in AZIMUTHS]
    onnx = tmp_path / "m.onnx"
    assert run_cli(["export", "--model", str(model), "--recognizer", "--out", str(onnx)], capsys)[0] == 0
    answers = []
    for source in (["--model", str(model)], ["--onnx", str(onnx)]):
        out = tmp_path / "p.json"
        code, _, err = run_cli(["predict", *source, *images, "--json", str(out)], capsys)
        assert code == 0, err
        answers.append([(p["label"], p["pose"]) for p in json.loads(out.read_text())])
    assert answers[0] == answers[1]  # the torch-free path masks as the torch one does
    assert sum(label == n for (label, _), n in zip(answers[0], ["egg"] * 5 + ["head"] * 5, strict=True)) >= 8


def test_bad_masks_and_colours_name_the_line_and_the_file(
    views: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    skimage.io.imsave(views / "empty.png", np.zeros((SIDE, SIDE), np.uint8), check_contrast=False)
    rows = (views / "views.csv").read_text().splitlines()
    for n in (2, 3):  # egg at -20 and -10: an all-background mask
        rows[n - 1] = rows[n - 1].rsplit(",", 1)[0] + ",empty.png"
    bad = views / "bad.csv"
    bad.write_text("\n".join(rows) + "\n")
    model = tmp_path / "m.pt"
    assert run_cli(_fit(views, "views.csv", model, "--background", "auto"), capsys)[0] == 0
    report = tmp_path / "r.json"
    code, _, err = run_cli(
        ["evaluate", "--model", str(model), "--manifest", str(bad), "--json", str(report)], capsys
    )
    assert code == 1
    record = json.loads(report.read_text())
    assert {r["row"] for r in record["skipped"]} == {f"{bad} line 2", f"{bad} line 3"}
    assert "egg-20.png" in err and "masks[0] is all background" in err
    assert record["n_test"] == 2 * len(AZIMUTHS) - 2  # the rest went on
    rows[3] = rows[3].rsplit(",", 1)[0] + ",empty.png"  # line 4: the seed egg at 0
    bad.write_text("\n".join(rows) + "\n")
    code, _, err = run_cli(_fit(views, "bad.csv", tmp_path / "x.pt", "--background", "auto"), capsys)
    assert code == 2 and f"{bad} line 4" in err and "egg0.png" in err and "all background" in err
    code, _, err = run_cli(_fit(views, "nomask.csv", tmp_path / "x.pt", "--background", "128,128,128", "--tolerance", "400"), capsys)  # fmt: skip
    assert code == 2 and "nomask.csv line" in err and "egg0.png" in err and "(given) leaves no object" in err
    code, _, err = run_cli(_fit(views, "views.csv", tmp_path / "x.pt", "--background", "0,0,0", "--tolerance", "500"), capsys)  # fmt: skip
    assert code == 2 and "--tolerance '500' must be a number" in err
    code, _, err = run_cli(_fit(views, "views.csv", tmp_path / "x.pt", "--tolerance", "10"), capsys)
    assert code == 2 and "--tolerance goes with --background auto or R,G,B" in err


def test_background_option_and_record() -> None:
    assert background_arg("auto") == "auto" and background_arg("keep") == "keep"
    assert background_arg("255,0,51") == (1.0, 0.0, 0.2)
    for text in ("blue", "1,2", "0,0,256", "nan,0,0"):
        with pytest.raises(
            argparse.ArgumentTypeError, match=f"--background '{text}' must be keep, auto, or a colour"
        ):
            background_arg(text)
    prep = Preprocessing((8, 8), 1, background="colour", colour=(0.1, 0.3, 0.7), tolerance=0.1)
    assert Preprocessing.from_json(json.loads(json.dumps(prep.to_json()))) == prep
    old = {
        "size": [8, 8],
        "channels": 1,
        "background": "keep",
        "unit_norm": True,
        "resize": "bilinear-antialias",
    }
    assert (
        Preprocessing.from_json(old) == Preprocessing((8, 8), 1) and Preprocessing((8, 8), 1).to_json() == old
    )
    with pytest.raises(ValueError, match="colour must be given with background='colour' and only then"):
        Preprocessing((8, 8), 1, background="colour")
    with pytest.raises(ValueError, match=r"colour must be 1 or 3 values in \[0, 1\], got \(0.1, 2.0\)"):
        Preprocessing((8, 8), 1, background="colour", colour=(0.1, 2.0))
    with pytest.raises(ValueError, match="tolerance goes with background 'auto' or 'colour', not 'keep'"):
        Preprocessing((8, 8), 1, tolerance=0.1)
    with pytest.raises(
        ValueError, match=r"damaged preprocessing record: .*tolerance must be a positive number"
    ):
        Preprocessing.from_json({**old, "background": "auto", "tolerance": -1}, "m.pt")


def test_default_background_keeps_views_without_masks(
    views: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, err = run_cli(_fit(views, "nomask.csv", tmp_path / "m.pt"), capsys)
    assert code == 0, err
    assert "background keep (no masks given)" in out
    _, meta = load_recognizer(tmp_path / "m.pt")
    assert Preprocessing.from_json(meta["preprocessing"]).background == "keep"


def test_memory_check_refuses_before_any_work(
    views: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A fit that would need more than is available stops at once, naming the sizes and the
    command's remedies, and writes nothing."""
    import torch_eigview.method.memory as memory

    monkeypatch.setattr(memory, "available_memory", lambda: (1 << 20, "the address-space limit, ulimit -v"))
    out = tmp_path / "m.pt"
    code, _, err = run_cli(_fit(views, "views.csv", out), capsys)
    assert code == 2 and not out.exists()
    assert "the fit needs about" in err and "but only 0.00 GiB are available (the address-space limit" in err
    assert "2 objects x 21 views and 36 held out" in err and "(C, H, W)=(1, 32, 32)" in err
    assert "--size H W" in err and "--synth" in err
