"""The full circle on COIL-20: M seed views all round the turntable, every other pose tested.

For each M: M seed views 360°/M apart from 0° (``eigview coil --seeds M``), every sector
between consecutive seeds synthesized (the one from the last seed back to the first
included) every ``--step`` degrees, one eigenspace of 20 components, 1-NN over every
pose that is not a seed (72 − M per object). Beside it the baselines: ``sparse``, the M
seed views alone, and ``dense``, real views about every 180°/M (about 2M per object,
tested on the other poses). The pose of a recognized view is interpolated on the
appearance manifold between the nearest gallery view and its neighbours; the table gives
the mean and median absolute pose error of the recognized ``nvs`` views and the whole
``nvs`` run's seconds.

Run: ``python examples/full_circle.py [--root ../shared/data/coil-20-proc] [--seeds 4 6 8 12] [--step 5]``
(each row is three ``eigview coil --seeds M --components 20 --synth 0 0 STEP`` runs, with
``--method nvs``, ``sparse`` and ``dense``).
"""

from __future__ import annotations

import argparse

from torch_eigview import CoilFolder
from torch_eigview.apps.diagnose import circle_table
from torch_eigview.datasets import find_coil_root


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--root",
        help="the COIL-20 folder (default: coil-20-proc/ in $TORCH_EIGVIEW_DATA, else ../shared/data/coil-20-proc)",
    )
    parser.add_argument("--seeds", type=int, nargs="+", default=[4, 6, 8, 12], help="values of M")
    parser.add_argument("--step", type=float, default=5.0, help="synthesized step, degrees")
    parser.add_argument("--components", type=int, default=20)
    args = parser.parse_args(argv)
    try:  # a missing folder: say where the images go, not a traceback
        folder = CoilFolder(find_coil_root(args.root))
    except ValueError as exc:
        parser.error(str(exc))
    print(circle_table(folder, folder.objects, args.seeds, args.components, args.step))


if __name__ == "__main__":
    main()
