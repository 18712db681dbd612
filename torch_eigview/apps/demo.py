"""The paper's synthetic recognition experiment (Sec. 5.1, Fig. 2) on the embedded objects.

Five synthetic objects (:data:`~torch_eigview.datasets.shapes.SHAPES`) are rendered by the
orthographic camera. Per object, two seed views (0° and α; three views at −α, 0°, α) give
the views synthesized every 1° (Eq. 2, 7; :func:`~torch_eigview.synthesis.synthesize_views`
with flow-estimated or exact correspondences); one eigenspace of 15 components spans all
objects' synthesized views, and the 90 rendered test views per object (−45°..44°, 1°) are
recognized by their nearest neighbour: the protocol of the COIL experiment
(:mod:`torch_eigview.evaluation.scoring`). :func:`run_demo` prints Fig. 2(ii)'s per-object table
and draws the eigenimages and, for one object, synthesized views beside rendered ones
(Fig. 2(f–o)).
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Iterable, Iterator, Sequence

import torch

from torch_eigview.apps.synthetic_scene import (
    SyntheticScene,
    _gallery_angles,
    default_camera,
    synthesis_error,
    synthetic_gallery,
)
from torch_eigview.check import check_choice
from torch_eigview.datasets import SHAPES, OrthographicCamera
from torch_eigview.datasets.backdrop import Backdrop
from torch_eigview.evaluation.scoring import angle_range, build_recognizer, score, stack_gallery
from torch_eigview.files import atomic_open, check_output_path
from torch_eigview.lazy import require
from torch_eigview.nn.projection import EigenProjection
from torch_eigview.nn.recognition import NearestNeighborRecognizer

__all__ = [
    "SyntheticScene",
    "default_camera",
    "recognition_experiment",
    "run_demo",
    "synthesis_error",
    "synthetic_gallery",
]


def recognition_experiment(
    alpha: float = 10.0,
    n_views: int = 2,
    *,
    scene: SyntheticScene | None = None,
    components: int | float = 15,
    correspondences: str = "flow",
    synth: tuple[float, float, float] | None = None,
    test: tuple[float, float] = (-45.0, 44.0),
    progress: Callable[[Iterable[str]], Iterable[str]] | None = None,
) -> dict[str, object]:
    """Fig. 2(ii): one eigenspace of all objects' synthesized views, 1-NN on rendered views.

    Args:
        alpha: angle between seed views in degrees.
        n_views: 2 or 3 seed views per object.
        scene: objects and camera (default: the five objects at 64×64).
        components: eigenspace dimension k (or an energy fraction).
        correspondences: ``"flow"``, ``"exact"`` or ``"rendered"`` (the protocol's
            ceiling), see :func:`synthetic_gallery`.
        synth: synthesized angles (start, stop, step), see :func:`synthetic_gallery`.
        test: (start, stop) of the test views, every 1°.
        progress: optional wrapper over the loop of objects whose views are synthesized
            (e.g. ``tqdm.tqdm``).

    Returns:
        A dict with ``accuracy`` (%), ``per_object`` (name → %), ``pose_mae_deg`` (mean
        absolute pose error of the recognized test views), ``n_test``, ``n_gallery``,
        ``seconds`` and the ``recognizer``.
    """
    scene = scene or SyntheticScene()
    t_start = time.perf_counter()
    names = progress(scene.shapes) if progress else scene.shapes
    x, labels, poses = stack_gallery(_gallery_blocks(scene, names, alpha, n_views, synth, correspondences))
    t_gallery = time.perf_counter()
    try:
        recognizer = build_recognizer(x, labels, poses, components, label_names=list(scene.shapes))
    except ValueError as exc:
        if "exceeds the rank" not in str(exc):
            raise
        # The cause is the scene the command line chose, not an argument of the eigenspace.
        raise ValueError(
            f"the {len(scene.shapes)} object(s) rendered at {tuple(x.shape[-2:])} pixels give too few distinct "
            f"views for {components} eigenspace components ({exc}): render larger views (--size) or more "
            f"objects (--shapes)"
        ) from exc
    test_angles = angle_range(test[0], test[1], 1.0, name="test")
    truth = torch.tensor(test_angles, dtype=x.dtype)
    result = score(
        recognizer, ((name, i, scene.views(name, test_angles), truth) for i, name in enumerate(scene.shapes))
    )
    t_end = time.perf_counter()
    return {
        "alpha": alpha,
        "n_views": n_views,
        "correspondences": correspondences,
        "accuracy": result.accuracy,
        "per_object": result.per_object,
        "pose_mae_deg": result.pose_mae_deg,
        "n_test": result.n_test,
        "n_gallery": x.shape[0],
        "seconds": {
            "gallery": t_gallery - t_start,
            "recognition": t_end - t_gallery,
            "total": t_end - t_start,
        },
        "recognizer": recognizer,
    }


def _gallery_blocks(
    scene: SyntheticScene,
    names: Iterable[str],
    alpha: float,
    n_views: int,
    synth: tuple[float, float, float] | None,
    correspondences: str,
) -> Iterator[tuple[torch.Tensor, int, list[float]]]:
    """Per object of ``names`` (the scene's, in order), its synthesized views, index and angles,
    one thread per CPU and object (torch kernels release the GIL)."""
    from torch_eigview.scale.parallel import map_ordered, object_workers

    workers = object_workers(0, 0, len(scene.shapes), kind="thread")
    jobs = ((scene, name, alpha, n_views, synth, correspondences) for name in scene.shapes)
    results = map_ordered(synthetic_gallery, jobs, workers, kind="thread")
    with contextlib.closing(results):  # an error here ends the pool
        for i, (_, (views, thetas)) in enumerate(zip(names, results, strict=True)):
            yield views, i, thetas


def format_table(
    results: Sequence[dict[str, object]], paper: dict[tuple[float, int], float] | None = None
) -> str:
    """Fig. 2(ii) as text: α, N, correspondences, accuracy per object, total (and the paper's)."""
    first = results[0]["per_object"]
    assert isinstance(first, dict)
    names = list(first)
    head = f"{'alpha':>5} {'N':>2} {'corr':>8} " + " ".join(f"O{i + 1:<6}" for i in range(len(names)))
    head += f" {'Total(%)':>8}" + (f" {'paper':>6}" if paper is not None else "")
    lines = [head]
    for r in results:
        per = r["per_object"]
        assert isinstance(per, dict)
        line = f"{r['alpha']:>5g} {r['n_views']:>2} {r['correspondences']:>8} "
        line += " ".join(f"{per[n]:<7.2f}" for n in names) + f" {r['accuracy']:>8.2f}"
        if paper is not None:
            ref = paper.get((float(r["alpha"]), int(r["n_views"])))  # type: ignore[arg-type, call-overload]
            line += f" {ref:>6.2f}" if ref is not None else f" {'-':>6}"
        lines.append(line)
    legend = ", ".join(f"O{i + 1}={n}" for i, n in enumerate(names))
    return "\n".join([*lines, legend])


def run_demo(
    out_png: str | None = "eigview_demo.png",
    alpha: float = 10.0,
    *,
    size: int = 64,
    correspondences: str = "flow",
    verbose: bool = True,
    progress: Callable[[Iterable[str]], Iterable[str]] | None = None,
) -> dict[str, object]:
    """The embedded demo: Fig. 2 of the paper on the five synthetic objects.

    Two seed views per object (0° and ``alpha``), the eigenspace of the views synthesized
    over −20°..20° every 1° (15 components), nearest-neighbour recognition of the 450
    rendered test views (−45°..44°); prints the per-object table of Fig. 2(ii) and writes
    a figure with the objects, the eigenimages and, for the first object, synthesized
    views beside rendered ones (Fig. 2(f–o)).

    Args:
        out_png: path of the figure, or None for none (needs matplotlib; without it the
            figure is skipped with a message); checked before the run, replaced atomically.
        alpha: angle between the two seed views in degrees.
        size: image side in pixels.
        correspondences: ``"flow"`` or ``"exact"``.
        verbose: print the table.
        progress: optional wrapper over the object loop (e.g. ``tqdm.tqdm``).

    Returns:
        The :func:`recognition_experiment` record (without the recognizer) plus
        ``"figure"`` (the path written, or None).
    """
    if out_png is not None:
        check_output_path(out_png, "out_png")  # before the run, not after it
    scene = SyntheticScene(camera=OrthographicCamera(size))
    result = recognition_experiment(alpha, 2, scene=scene, correspondences=correspondences, progress=progress)
    recognizer = result.pop("recognizer")
    assert isinstance(recognizer, NearestNeighborRecognizer)
    if verbose:
        print(format_table([result], {(alpha, 2): _PAPER_N2[alpha]} if alpha in _PAPER_N2 else None))
        secs = result["seconds"]
        assert isinstance(secs, dict)
        print(
            f"accuracy {result['accuracy']:.2f}% of {result['n_test']} test views, "
            f"pose error {result['pose_mae_deg']:.2f} deg, {secs['total']:.1f} s"
        )
    result["figure"] = None
    if out_png is not None:
        try:
            matplotlib = require("matplotlib", "plot", "the demo's figure")
        except ImportError as exc:
            print(f"{exc}; the figure is skipped")
        else:
            matplotlib.use("Agg")
            result["figure"] = _figure(out_png, scene, recognizer, alpha, correspondences)
            if verbose:
                print(f"figure written to {out_png}")
    return result


#: The backgrounds of ``eigview synth``: the paper's black one, or a coloured, textured backdrop.
BACKGROUNDS = ("black", "textured")

_PAPER_N2 = {5.0: 100.0, 10.0: 100.0, 15.0: 99.33, 20.0: 96.44, 30.0: 93.77}
#: Fig. 2(ii) of the paper, (alpha, N) -> accuracy (%).
PAPER_FIG2 = {**{(a, 2): v for a, v in _PAPER_N2.items()}, (20.0, 3): 100.0, (30.0, 3): 100.0}


def run_synth(
    camera: str = "orthographic",
    alphas: Sequence[float] = (5.0, 10.0, 15.0, 20.0, 30.0),
    views: Sequence[int] = (2, 3),
    *,
    size: int = 64,
    correspondences: str = "flow",
    error_thetas: Sequence[float] = (-15.0, -5.0, 4.0, 15.0),
    error_alpha: float = 10.0,
    shapes: Sequence[str] = SHAPES,
    test: tuple[float, float] = (-45.0, 44.0),
    verbose: bool = True,
    progress: Callable[[Iterable[tuple[int, float]]], Iterable[tuple[int, float]]] | None = None,
    background: str = "black",
    masks: str = "given",
) -> dict[str, object]:
    """The Fig. 2 protocol for one camera model (``eigview synth --camera``).

    For each α and number of seed views N: the eigenspace of the views synthesized with
    this camera's model (Eq. 7, the affine solve or trifocal transfer) and 1-NN on the
    rendered test views, as :func:`recognition_experiment`; then the per-pixel error of
    views synthesized from seeds 0° and ``error_alpha`` with exact correspondences
    against the renders (:func:`synthesis_error`), per object.

    The ``ceiling`` records run the same protocol on the rendered views at the gallery's
    angles (``correspondences="rendered"``): what perfect synthesis would reach.
    ``progress`` optionally wraps the loop over the (N, α) runs (e.g. ``tqdm.tqdm``).

    ``background="textured"`` renders every view on the coloured, textured
    :class:`~torch_eigview.datasets.backdrop.Backdrop`, and ``masks`` (``"given"``: the
    renderer's, ``"estimated"``: the background model's) decides each view's foreground
    before its background is set to 0 (see :class:`SyntheticScene`); ``"black"`` is the
    paper's black background.

    Returns:
        ``{"camera", "results": [records without recognizers], "ceiling": [same], "synthesis_error":
        {object: [errors per angle]}, "error_thetas", "seconds"}``.
    """
    t0 = time.perf_counter()
    check_choice(background, "background", BACKGROUNDS)
    backdrop = Backdrop() if background == "textured" else None
    scene = SyntheticScene(
        shapes=tuple(shapes), camera=default_camera(camera, size), backdrop=backdrop, masks=masks
    )
    results, ceiling = [], []
    by_angles: dict[tuple[float, ...], dict[str, object]] = {}  # the ceiling depends on the angles only
    runs = [(n, alpha) for n in views for alpha in alphas]
    for n, alpha in progress(runs) if progress else runs:
        record = recognition_experiment(alpha, n, scene=scene, correspondences=correspondences, test=test)
        record.pop("recognizer")
        results.append(record)
        angles = tuple(_gallery_angles(alpha, n, None)[1])
        if angles not in by_angles:
            by_angles[angles] = recognition_experiment(
                alpha, n, scene=scene, correspondences="rendered", test=test
            )
            by_angles[angles].pop("recognizer")
        ceiling.append({**by_angles[angles], "alpha": alpha})
    errors = {name: synthesis_error(scene, name, error_alpha, error_thetas) for name in scene.shapes}
    out = {
        "camera": camera,
        "size": size,
        "background": background,
        "masks": masks if backdrop is not None else None,
        "results": results,
        "ceiling": ceiling,
        "synthesis_error": errors,
        "error_thetas": list(error_thetas),
        "error_alpha": error_alpha,
        "seconds": time.perf_counter() - t0,
    }
    if verbose:
        on = "black background" if backdrop is None else f"textured background, {masks} masks"
        print(f"camera model: {camera} ({size}x{size}), {correspondences} correspondences, {on}")
        print(format_table(results, PAPER_FIG2))
        print("ceiling: the same protocol with the rendered views at the gallery's angles (no synthesis):")
        print(format_table(ceiling, PAPER_FIG2))
        print(
            f"per-pixel mean abs error of synthesized vs rendered views (exact correspondences, "
            f"seeds 0 and {error_alpha:g} deg, pixels both seeds see; 0.01 = 1%):"
        )
        print(f"{'object':>13} " + " ".join(f"{t:>7g}" for t in error_thetas) + "    mean")
        for name, errs in errors.items():
            print(f"{name:>13} " + " ".join(f"{e:7.4f}" for e in errs) + f" {sum(errs) / len(errs):7.4f}")
        every = [e for errs in errors.values() for e in errs]
        print(
            f"{'all':>13} mean {sum(every) / len(every):.4f}, max {max(every):.4f}; {out['seconds']:.1f} s in all"
        )
    return out


def _figure(
    path: str, scene: SyntheticScene, recognizer: NearestNeighborRecognizer, alpha: float, corr: str
) -> str:
    import matplotlib.pyplot as plt

    projection = recognizer.projection
    assert isinstance(projection, EigenProjection)
    _, h, w = projection.image_shape or (1, scene.camera.height, scene.camera.width)
    eigen = projection.components[:5].reshape(-1, h, w)
    name = scene.shapes[0]
    angles = [-20.0, -10.0, 5.0, 15.0, 20.0]
    synth, thetas = synthetic_gallery(scene, name, alpha, 2, correspondences=corr)
    picked = torch.stack([synth[thetas.index(a)] for a in angles])
    rendered = scene.views(name, angles)
    n_col = max(len(scene.shapes), len(angles), eigen.shape[0])
    fig, axes = plt.subplots(4, n_col, figsize=(1.8 * n_col, 7.6))
    for ax in axes.flat:
        ax.axis("off")
    for j, shape in enumerate(scene.shapes):
        axes[0, j].imshow(scene.views(shape, [0.0])[0, 0], cmap="gray", vmin=0, vmax=1)
        axes[0, j].set_title(f"O{j + 1} {shape}", fontsize=8)
    for j in range(eigen.shape[0]):
        axes[1, j].imshow(eigen[j], cmap="RdBu_r")
        axes[1, j].set_title(f"eigenimage {j + 1}", fontsize=8)
    for j, a in enumerate(angles):
        axes[2, j].imshow(picked[j, 0], cmap="gray", vmin=0, vmax=1)
        axes[2, j].set_title(f"synthesized {a:g}°", fontsize=8)
        axes[3, j].imshow(rendered[j, 0], cmap="gray", vmin=0, vmax=1)
        axes[3, j].set_title(f"rendered {a:g}°", fontsize=8)
    fig.suptitle(f"Fig. 2: seeds at 0° and {alpha:g}° ({corr} correspondences)", fontsize=10)
    fig.tight_layout()
    with atomic_open(path, "wb") as fh:
        fig.savefig(fh, format="png", dpi=90)
    plt.close(fig)
    return path
