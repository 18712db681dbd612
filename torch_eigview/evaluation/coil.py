"""The paper's COIL experiment (Sec. 5.2, Fig. 4(b)) on a folder of COIL-style images.

Per object: seed views at ``center``, ``center + α`` (and ``center + 2α`` for three
views); the views over the gallery range are synthesized (``nvs``), or the baseline
eigenspace uses the seed views alone (``sparse``) or the real views every 5° over the
gallery range (``dense``). One eigenspace is fitted over all objects' gallery views, and
every real view every 5° over ``test`` (around ``center``) is recognized by its nearest
neighbour. The gallery, the eigenspace and the recognizer are those of
:class:`~torch_eigview.method.FewViewEigenspace` (:meth:`CoilExperiment.estimator`), the
pipeline every command builds through; the experiment adds the folder's views and the score.

The gallery range is ``synth`` for two seed views. With more, it follows the seeds'
span (:meth:`CoilExperiment.synth_angles`): each further seed extends it by α on its
side, so that it keeps the margins ``synth`` gives two views, ``-start`` before the first
seed and ``stop - α`` past the last (α > 0). Without that the default −20°..20° would
stop short of a third seed at 2α = 30° (α = 15°): that seed's pair would only
interpolate 15°..20°, where the first pair's extrapolation is as good, and the extra
view would bring no coverage. The step stays, so the gallery grows with the span (41
views per object for two seeds at 1° steps, 41 + α for three), as the paper's SOIL
experiment grows it with 2α.

With ``seeds`` = M the experiment goes round the whole turntable instead
(:mod:`torch_eigview.evaluation.circle`): M seed views 360°/M apart from ``center``, every
sector synthesized (every ``synth`` step), one eigenspace, and every available pose that
holds no real gallery view tested; ``sparse`` is the M seeds alone and ``dense`` the real
views every ``dense_step`` degrees.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field

import torch

from torch_eigview.check import (
    VIEW_LIMIT,
    check_alpha,
    check_choice,
    check_int,
    check_limit,
    check_n_components,
    check_number,
)
from torch_eigview.datasets.coil import CoilFolder
from torch_eigview.decomposition.kernel import KernelEigenspace
from torch_eigview.evaluation.circle import CircleLayout, circle_layout, grid_step
from torch_eigview.evaluation.coil_result import CoilResult
from torch_eigview.evaluation.scoring import score
from torch_eigview.evaluation.seed_pose import SeedPoses
from torch_eigview.geometry.angles import angle_range, wrap_angle, wrap_degrees
from torch_eigview.method.estimator import FewViewEigenspace
from torch_eigview.scale.parallel import KINDS
from torch_eigview.synthesis import Circle, SynthesisOptions, check_overlap

__all__ = ["CoilExperiment", "CoilResult", "angle_range", "wrap_degrees"]

METHODS = ("nvs", "sparse", "dense")


def _check_angles(values: object, name: str, size: int, layout: str) -> None:
    """``values`` must be ``size`` finite numbers of degrees, ``layout`` naming them."""
    if not isinstance(values, (tuple, list)) or len(values) != size:
        raise ValueError(f"{name} must be {layout} in degrees, got {values!r}")
    for v in values:
        if not math.isfinite(check_number(v, name)):
            raise ValueError(f"{name}={tuple(values)!r} must hold finite numbers of degrees {layout}")


@dataclass
class CoilExperiment:
    """Configuration of the COIL experiment; ``run(folder)`` carries it out.

    Attributes:
        alpha: angle between seed views in degrees.
        center: pose (degrees) of the first seed view and of the test range's centre.
        views: number of seed views (2 or 3).
        synth: (start, stop, step) of the synthesized angles (``nvs``; ``dense`` takes
            the real views every 5° over the same range), degrees relative to ``center``,
            for two seed views; see ``synth_follows_seeds`` for more.
        test: (start, stop) of the test range relative to ``center``, every 5 degrees.
        components: eigenspace dimension k (int) or energy fraction (float in (0, 1)).
        method: ``"nvs"``, ``"sparse"`` or ``"dense"``.
        objects: object ids, or None for all in the folder.
        unit_norm: L2-normalize every view (gallery and test) before the eigenspace.
        synthesis: options of the novel-view synthesis.
        kernel: None for the linear eigenspace (the paper's), or "rbf", "poly", "cosine",
            "linear" for a :class:`KernelEigenspace` over the same gallery.
        gamma: the kernel's γ (None: 1/N; "median": 1/median squared distance, rbf only).
        synth_follows_seeds: with more than two seed views, extend ``synth`` by
            (views − 2)·α on the side the seeds extend to (the stop for α > 0, the start
            for α < 0), so that the range keeps its margins beyond the first and the last
            seed; False takes ``synth`` as it is whatever the number of views.
        seeds: None, or M >= 2 for the full circle (M seed views 360°/M apart from
            ``center``; ``views``, ``alpha``'s value and the ranges other than ``synth``'s
            step are then unused; ``views`` must stay 2).
        dense_step: the full circle's ``dense`` step in degrees (default: the largest multiple
            of the poses' step up to 180/M, about 2M real views).
        interpolate_pose: score the pose interpolated on the appearance manifold between
            the nearest gallery view and its neighbours
            (:meth:`~torch_eigview.nn.recognition.NearestNeighborRecognizer.interpolate_poses`),
            not the nearest view's pose.
        three_view_pose: then measure each pose by geometry from the pose above, against
            the recognized object's seeds (:class:`~torch_eigview.evaluation.seed_pose.SeedPoses`,
            two flows per view, about what synthesizing a view costs); not with ``seeds=2``
            (Eq. 2 is singular).
        overlap: with ``seeds``, degrees each seed pair extrapolates past its seeds
            (:func:`~torch_eigview.evaluation.circle.synthesize_circle`), 0 for none.
        workers: workers that synthesize the ``nvs`` galleries, a few objects each at a
            time, their flows batched (:func:`~torch_eigview.scale.parallel.group_size`),
            and as threads measure the geometric poses (``three_view_pose``)
            (:func:`~torch_eigview.scale.parallel.map_ordered`; processes run one torch
            thread each, threads torch's current setting: the commands run them under
            ``threads(1)``, and a script should too); 0
            (the default) synthesizes in this process. CPU only: a folder on another
            device synthesizes in this process. The views are the same either way.
        worker_kind: ``"thread"`` (the default: threads of this process, no start-up cost;
            the flow and the warp run in torch kernels, which release the GIL) or
            ``"process"`` (spawned processes, for flows that hold the GIL: ``ilk``,
            ``tvl1-skimage``).
    """

    alpha: float = 5.0
    center: float = 0.0
    views: int = 2
    synth: tuple[float, float, float] = (-20.0, 20.0, 1.0)
    test: tuple[float, float] = (-45.0, 45.0)
    components: int | float = 15
    method: str = "nvs"
    objects: Sequence[int] | None = None
    unit_norm: bool = True
    synthesis: SynthesisOptions = field(default_factory=SynthesisOptions)
    kernel: str | None = None
    gamma: float | str | None = None
    synth_follows_seeds: bool = True
    seeds: int | None = None
    dense_step: float | None = None
    interpolate_pose: bool = False
    three_view_pose: bool = False
    overlap: float = 0.0
    workers: int = 0
    worker_kind: str = "thread"

    def __post_init__(self) -> None:
        check_int(self.workers, "workers", minimum=0)
        check_choice(self.worker_kind, "worker_kind", KINDS)
        if self.kernel is not None:
            # Validates both (stored as given, checked when a fit starts: here, before any work).
            KernelEigenspace(self.components, kernel=self.kernel, gamma=self.gamma)._validate_params()
        elif self.gamma is not None:
            raise ValueError(f"gamma={self.gamma!r} needs a kernel (kernel is None)")
        if self.seeds is None:  # the full circle sets its own angles
            check_alpha(self.alpha)
        if self.views not in (2, 3) or isinstance(self.views, bool):
            raise ValueError(f"views must be 2 or 3, got {self.views!r}")
        if not math.isfinite(check_number(self.center, "center")):
            raise ValueError(f"center={self.center!r} must be a finite number of degrees")
        _check_angles(self.synth, "synth", 3, "(start, stop, step)")
        _check_angles(self.test, "test", 2, "(start, stop)")
        if self.seeds is None and abs(self.alpha) * (self.views - 1) >= 180:
            raise ValueError(f"alpha={self.alpha} with {self.views} seed views spans 180 degrees or more")
        check_n_components(self.components)
        if self.method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {self.method!r}")
        if not isinstance(self.synth_follows_seeds, bool):
            raise TypeError(f"synth_follows_seeds must be a bool, got {self.synth_follows_seeds!r}")
        # Bounded before any list is built: a tiny step would ask for billions of views.
        start, stop = self.synth_range()
        if self.synth[2] > 0:  # else angle_range names the bad step
            # "dense" takes the real views every 5 degrees over the same range.
            step = min(self.synth[2], 5.0)
            check_limit((stop - start) / step + 1, "synth", "views per object", VIEW_LIMIT)
        check_limit((self.test[1] - self.test[0]) / 5.0 + 1, "test", "test views per object", VIEW_LIMIT)
        angle_range(*self.synth, name="synth")
        angle_range(self.test[0], self.test[1], 5.0, name="test")
        if not isinstance(self.interpolate_pose, bool) or not isinstance(self.three_view_pose, bool):
            raise TypeError(
                f"interpolate_pose, three_view_pose must be bools: {self.interpolate_pose!r}, {self.three_view_pose!r}"
            )
        if self.seeds is not None:
            check_int(self.seeds, "seeds", minimum=2)
            if self.views != 2:
                raise ValueError(
                    f"seeds={self.seeds} places its own seed views: it cannot take views={self.views}"
                )
        if check_number(self.overlap, "overlap") != 0 and self.seeds is None:
            raise ValueError(f"overlap={self.overlap} extends the full circle's sectors: it needs seeds")
        if self.dense_step is not None and (self.seeds is None or self.method != "dense"):
            raise ValueError(
                f"dense_step={self.dense_step} is the full circle's dense baseline: it needs seeds and "
                f"method 'dense', got seeds={self.seeds}, method={self.method!r}"
            )

    def synth_range(self) -> tuple[float, float]:
        """(start, stop) of the gallery range in degrees relative to ``center``.

        ``synth``'s for two seed views; for m views (``synth_follows_seeds``) extended by
        (m − 2)·α on the seeds' side: ``(start, stop + (m − 2)·α)`` for α > 0.
        """
        start, stop, _ = self.synth
        if not self.synth_follows_seeds:
            return start, stop
        extra = (self.views - 2) * self.alpha
        return start + min(extra, 0.0), stop + max(extra, 0.0)

    def synth_angles(self, step: float | None = None) -> list[float]:
        """The gallery angles relative to ``center``: :meth:`synth_range` every ``step``
        degrees (default ``synth``'s step)."""
        start, stop = self.synth_range()
        return angle_range(start, stop, self.synth[2] if step is None else step, "synth")

    @property
    def _center(self) -> float:
        """``center`` wrapped to (-180, 180] in float64: poses then stay exact in the views'
        float32 (1e9 degrees would not)."""
        return wrap_angle(self.center)

    def seed_poses(self, layout: CircleLayout | None = None) -> list[float]:
        """The seed views' poses in degrees: the full circle's (``layout``), else ``center`` + n·α."""
        return (
            layout.seeds if layout is not None else [self._center + n * self.alpha for n in range(self.views)]
        )

    def circle(
        self,
        folder: CoilFolder,
        objects: Sequence[int] | None = None,
        names: tuple[str, str] = ("seeds", "dense_step"),
    ) -> CircleLayout:
        """The full circle's layout (``seeds`` set) over the poses every object has;
        ``names`` name ``seeds`` and ``dense_step`` in errors.

        Raises:
            ValueError: see :func:`~torch_eigview.evaluation.circle.circle_layout`.
        """
        if self.seeds is None:
            raise ValueError("circle() needs seeds (the full circle's number of seed views), got None")
        objs = folder.objects if objects is None else objects
        common = set.intersection(*(set(folder.poses(obj)) for obj in objs))
        layout = circle_layout(sorted(common), self._center, self.seeds, self.method, self.dense_step, names)
        if self.overlap != 0:
            check_overlap(self.seeds, self.overlap, "overlap")
        return layout

    def _gallery_inputs(
        self, folder: CoilFolder, objects: list[int], layout: CircleLayout | None
    ) -> tuple[list[torch.Tensor], list[list[float]]]:
        """Per object the views the estimator is fitted on and their poses (degrees): the
        seed views (``nvs``, ``sparse``) or the real views every pose step over the
        gallery range (``dense``; the full circle's every dense step)."""
        if layout is not None:
            read = layout.seeds if self.method != "dense" else layout.real
            # The seeds' poses from the wrapped center, as the gallery's (the files' are mod 360).
            poses = (
                read
                if self.method == "dense"
                else [self._center + k * layout.alpha for k in range(len(read))]
            )
            return [folder.images(obj, read) for obj in objects], [list(poses) for _ in objects]
        views, angles = [], []
        for obj in objects:
            poses = self.seed_poses()
            if self.method == "dense":  # every real view in the synthesized range
                poses = [self._center + a for a in self.synth_angles(grid_step(folder.poses(obj)))]
            views.append(folder.images(obj, poses))
            angles.append(poses)
        return views, angles

    def _cpu_workers(self, folder: CoilFolder) -> int:
        """``workers`` for a run over ``folder``: the workers run on the CPU, none elsewhere."""
        return self.workers if folder.device.type == "cpu" else 0

    def estimator(
        self, folder: CoilFolder | None = None, layout: CircleLayout | None = None
    ) -> FewViewEigenspace:
        """The :class:`~torch_eigview.method.FewViewEigenspace` that builds this experiment's
        gallery, eigenspace and recognizer (``nvs``: synthesized from the seeds, ``sparse``
        and ``dense``: the real views alone); workers only for a folder on the CPU."""
        synth: tuple[float, float, float] | Circle | None = None
        if self.method == "nvs":
            synth = self.synth if layout is None else Circle(self.synth[2], self.overlap)
        return FewViewEigenspace(
            self.components,
            synth=synth,
            options=self.synthesis,
            unit_norm=self.unit_norm,
            kernel=self.kernel,
            gamma=self.gamma,
            synth_follows_seeds=self.synth_follows_seeds,
            workers=self.workers if folder is None else self._cpu_workers(folder),
            worker_kind=self.worker_kind,
        )

    def run(
        self,
        folder: CoilFolder,
        progress: Callable[[Iterable[int]], Iterable[int]] | None = None,
    ) -> CoilResult:
        """Builds the gallery and eigenspace, recognizes the test views, and reports.

        Args:
            folder: the images.
            progress: optional wrapper over the object loop (e.g. ``tqdm.tqdm``).
        """
        objects = list(folder.objects if self.objects is None else self.objects)
        missing = sorted(set(objects) - set(folder.objects))
        if missing:
            raise ValueError(f"objects {missing} are not in {folder.root} (it holds {folder.objects})")
        if not objects:
            raise ValueError("objects must name at least one object")
        layout = None if self.seeds is None else self.circle(folder, objects)
        seeds = self.seed_poses(layout)  # the pose function is built (and checked) before any work
        pose_fn = (
            SeedPoses(folder, seeds, layout is not None, self.synthesis) if self.three_view_pose else None
        )
        t_start = time.perf_counter()
        views, angles = self._gallery_inputs(folder, objects, layout)
        est = self.estimator(folder, layout).fit(views, angles, labels=objects, progress=progress)
        seconds = {
            "correspondence": est.seconds_.get("correspondence", 0.0),
            "synthesis": est.seconds_.get("synthesis", 0.0),
            "eigen": est.seconds_["eigen"],
        }
        t0 = time.perf_counter()
        if layout is None:
            step = grid_step([p for obj in objects for p in folder.poses(obj)])
            test_poses = [self._center + a for a in angle_range(self.test[0], self.test[1], step, "test")]
        else:
            test_poses = layout.tests
        tests = self._tests(folder, objects, test_poses, views[0].dtype)
        threads = self._cpu_workers(folder) if self.worker_kind == "thread" else 0
        result = score(
            est.recognizer_,
            tests,
            wrap=True,
            interpolate_pose=self.interpolate_pose,
            pose_fn=pose_fn,
            workers=threads,
        )
        seconds["recognition"] = time.perf_counter() - t0
        # Wall time of the whole run, reading the images included.
        seconds["total"] = time.perf_counter() - t_start
        return CoilResult(
            accuracy=result.accuracy,
            per_object=result.per_object,
            pose_mae_deg=result.pose_mae_deg,
            n_test=result.n_test,
            n_train_views=int(est.gallery_labels_.shape[0]),
            seconds=seconds,
            recognizer=est.recognizer_,
            elevations=dict(zip(objects, est.elevations_, strict=False)),
            pose_median_deg=result.pose_median_deg,
        )

    def _tests(
        self, folder: CoilFolder, objects: list[int], test_poses: list[float], dtype: torch.dtype
    ) -> Iterator[tuple[int, int, torch.Tensor, torch.Tensor]]:
        """Per object its real views at ``test_poses`` (degrees) and their poses (wrapped), read lazily."""
        for obj in objects:
            truth = wrap_degrees(torch.tensor(test_poses, dtype=torch.float64)).to(dtype)
            yield obj, obj, folder.images(obj, truth.tolist()), truth
