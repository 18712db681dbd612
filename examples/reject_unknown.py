"""Unknown objects on COIL-20: the ROC of the rejection and its calibrated operating point.

Objects 1–10 are known: two seed views (``center`` and ``center + α``, α = 10), the
paper's synthesized range −20°..20° (as ``eigview coil``), 15 components; the rejection is calibrated on views
synthesized at ``--reject-poses`` held out from the gallery (``FewViewEigenspace(
reject_rate=...)``). Objects 11–20 are unknown. Every real view at −45°..45° (5° steps)
around ``center`` of both halves is scored; the ROC is the fraction of unknown views
rejected against the fraction of known views rejected as the limit on the score moves
(the calibrated threshold is the limit 1). Also printed: recognition accuracy on the
accepted known views beside the accuracy without rejection.

Run: ``python examples/reject_unknown.py [--root DIR] [--json roc.json]``
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import torch

from torch_eigview import CoilFolder, FewViewEigenspace
from torch_eigview.datasets import find_coil_root


def roc(known: torch.Tensor, unknown: torch.Tensor) -> list[dict[str, float]]:
    """(rejected known, rejected unknown) fractions at every limit between distinct scores."""
    limits = torch.cat(
        [torch.tensor([0.0]), torch.cat([known, unknown]).unique(), torch.tensor([float("inf")])]
    )
    return [
        {
            "limit": float(c),
            "known_rejected": float((known > c).double().mean()),
            "unknown_rejected": float((unknown > c).double().mean()),
        }
        for c in limits
    ]


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", help="the COIL-20 folder (default: coil-20-proc/ in $TORCH_EIGVIEW_DATA)")
    parser.add_argument("--known", type=int, nargs="+", default=list(range(1, 11)), help="known objects")
    parser.add_argument("--unknown", type=int, nargs="+", default=list(range(11, 21)), help="unknown objects")
    parser.add_argument("--alpha", type=float, default=10.0)
    parser.add_argument("--center", type=float, default=0.0)
    parser.add_argument("--reject-rate", type=float, default=0.05)
    parser.add_argument("--reject-score", choices=("difs", "dffs", "both"), default="difs")
    parser.add_argument("--reject-poses", type=float, nargs=3, default=[-45.0, 45.0, 2.5])
    parser.add_argument("--json", help="write the ROC points and the operating point here")
    return parser


def main(argv: list[str] | None = None) -> dict[str, object]:
    parser = _parser()
    args = parser.parse_args(argv)
    try:  # a missing folder: say where the images go, not a traceback
        folder = CoilFolder(find_coil_root(args.root))
    except ValueError as exc:
        parser.error(str(exc))
    seeds = torch.stack([folder.images(o, [args.center, args.center + args.alpha]) for o in args.known])
    est = FewViewEigenspace(
        15,
        synth=(-20.0, 20.0, 1.0),  # the paper's range, as eigview coil (the default reaches 20 past seed 2)
        reject_rate=args.reject_rate,
        reject_score=args.reject_score,
        reject_poses=tuple(args.reject_poses),
    ).fit(seeds, [args.center, args.center + args.alpha], labels=args.known)
    poses = [args.center + p for p in range(-45, 46, 5)]
    known_views = torch.cat([folder.images(o, poses) for o in args.known])
    truth = torch.tensor(args.known).repeat_interleave(len(poses))
    unknown_views = torch.cat([folder.images(o, poses) for o in args.unknown])
    rec = est.predict(known_views, reject=True)
    assert rec.known is not None
    correct = rec.labels == truth
    score_known = est.recognizer_.rejection_scores(known_views)
    score_unknown = est.recognizer_.rejection_scores(unknown_views)
    points = roc(score_known, score_unknown)
    result: dict[str, object] = {
        "thresholds": [t if math.isfinite(t) else None for t in est.recognizer_.reject_thresholds.tolist()],
        "known_rejected": float((score_known > 1).double().mean()),
        "unknown_rejected": float((score_unknown > 1).double().mean()),
        "accuracy": float(correct.double().mean() * 100),
        "accuracy_accepted": float(correct[rec.known].double().mean() * 100),
        "n_known": len(truth),
        "n_unknown": len(unknown_views),
        "roc": points,
    }
    print(f"thresholds (t_dffs, t_difs): {result['thresholds']}")
    print(
        f"calibrated: {result['unknown_rejected']:.1%} of {result['n_unknown']} unknown views rejected, "
        f"{result['known_rejected']:.1%} of {result['n_known']} known views rejected"
    )
    print(
        f"accuracy: {result['accuracy']:.2f}% without rejection, {result['accuracy_accepted']:.2f}% on accepted"
    )
    for target in (0.01, 0.02, 0.05, 0.10):
        best = max((p for p in points if p["known_rejected"] <= target), key=lambda p: p["unknown_rejected"])
        print(f"ROC: known rejected <= {target:.0%}: unknown rejected {best['unknown_rejected']:.1%}")
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=2))
    return result


if __name__ == "__main__":
    main()
