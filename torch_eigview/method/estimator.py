"""The whole method as one estimator: seed views per object in, eigenspace and gallery out.

:class:`FewViewEigenspace` is the recognition pipeline, the one every command and
experiment of the package builds through (``eigview fit``, ``coil`` and ``demo``,
:class:`~torch_eigview.evaluation.CoilExperiment`): per object, the correspondences of
its seed views and the views synthesized over a range of angles
(:func:`~torch_eigview.synthesis.synthesize_views`, Sec. 4.1 sectors for more than two
seeds, or :func:`~torch_eigview.synthesis.synthesize_circle` all round the turntable),
over worker threads or processes when asked; one eigenspace over every object's gallery
views, each scaled to unit L2 norm (Murase and Nayar's brightness normalization); the
frozen projection layer; and the nearest-neighbour recognizer over the gallery's
coordinates (Sec. 4.2). With ``reject_rate``, ``fit`` also synthesizes views at poses held
out from the gallery and calibrates the recognizer's rejection of unknown objects on them
(:mod:`torch_eigview.method.rejection`).

It follows scikit-learn's conventions: hyperparameters are stored as given by
``__init__`` and validated by ``fit``, learned state ends in ``_``, ``fit`` returns self.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Hashable, Iterable, Iterator, Mapping, Sequence
from dataclasses import replace
from typing import Any

import torch

from torch_eigview.check import check_choice, check_int
from torch_eigview.decomposition.eigenspace import Eigenspace
from torch_eigview.decomposition.incremental import IncrementalEigenspace
from torch_eigview.decomposition.kernel import KernelEigenspace
from torch_eigview.decomposition.streaming import StreamingEigenspace
from torch_eigview.errors import NotFittedError
from torch_eigview.geometry.angles import AROUND_SEEDS, held_out_range, off_gallery
from torch_eigview.io.preprocessing import Preprocessing
from torch_eigview.method.gallery import GalleryFit
from torch_eigview.method.inputs import (
    Params,
    block_item,
    block_source,
    check_angles,
    check_circle_angles,
    check_labels,
    check_reach,
    check_seed_masks,
    check_seeds,
    check_synth,
    resolve_components,
    seed_steps,
    warn_unnormalized_seeds,
    wrap_degrees,
)
from torch_eigview.method.memory import check_memory, fit_estimate
from torch_eigview.method.rejection import (
    REJECT_SCORES,
    calibrate_rejection,
    check_reject_rate,
    estimate_reject_rate,
)
from torch_eigview.nn.functional import unit_rows
from torch_eigview.nn.kernel_projection import KernelProjection
from torch_eigview.nn.projection import EigenProjection
from torch_eigview.nn.recognition import NearestNeighborRecognizer, Recognition
from torch_eigview.scale.galleries import ObjectJob, object_galleries
from torch_eigview.scale.parallel import KINDS, group_size
from torch_eigview.scale.ranks import gather_in_rank_order, object_shard
from torch_eigview.synthesis import Circle, SynthesisOptions, SynthesizedViews, circle_thetas

__all__ = ["MEMORY_REMEDIES", "FewViewEigenspace"]

#: What a fit refused for its memory can change (:class:`~torch_eigview.method.memory.MemoryBudgetError`).
MEMORY_REMEDIES = (
    "give smaller images, fewer synthesized views (a coarser synth step) or, for a gallery held at once, "
    "a smaller max_views (the fit then merges it block by block)"
)


class FewViewEigenspace:
    """The paper's method from seed views to a fitted eigenspace and a recognizer.

    Args:
        n_components: eigenspace dimension k (int), energy fraction (float in (0, 1)), or
            None for every component above rounding (:data:`ALL_COMPONENTS`).
        synth: the synthesized angles: ``"around-seeds"`` (default,
            :data:`~torch_eigview.geometry.angles.AROUND_SEEDS`), every degree from 20°
            before each object's first seed view to 20° past its last; (start, stop,
            step) in degrees relative to the first seed view, for two seeds (see
            ``synth_follows_seeds``; ``(-20, 20, 1)`` is the paper's protocol);
            ``"circle"`` or a :class:`~torch_eigview.synthesis.Circle` (its step and
            overlap): M >= 3 seed views evenly spaced round the turntable, every sector
            synthesized (:func:`~torch_eigview.synthesis.synthesize_circle`); or None,
            which fits the seed views alone (the ``sparse`` baseline of the experiments,
            or any gallery of real views). At most 3600 views per object.
        options: :class:`~torch_eigview.synthesis.SynthesisOptions` (flow, elevation,
            extent, blend, silhouette, …); None for the defaults.
        unit_norm: scale every view to unit L2 norm before the eigenspace and in the layer
            (``to_module()`` gives a layer that does so, as every ``to_module`` gives the
            layer what its fit did to the views; an ``Eigenspace`` fits the rows as given,
            so its layer's default is False).
        kernel: None for the linear eigenspace (the paper's), or a
            :class:`~torch_eigview.decomposition.kernel.KernelEigenspace` kernel name.
        gamma: the kernel's γ (a number, "median" for rbf, or None: 1/N).
        degree: the degree of the ``"poly"`` kernel, an int >= 1 (other kernels ignore it).
        synth_follows_seeds: with more than two seeds, extend a (start, stop, step) ``synth`` on the seeds'
            side by the steps past the first pair (as ``CoilExperiment``).
        max_views: the most gallery views held at once. ``fit`` fits a gallery of at most
            this many views at once, its exact eigenspace; a larger one is merged as it is
            synthesized, a block of about ``max_rank`` views at a time
            (:class:`~torch_eigview.decomposition.incremental.IncrementalEigenspace`), so that
            its memory no longer grows with the number of objects (a kernel eigenspace is
            always fitted at once). :meth:`fit_blocks` holds at most this many per pass.
        max_rank: the most eigenpairs the merged eigenspace keeps (>= an int
            ``n_components``): up to it every merge is exact; past it each merge drops its
            smallest, and ``eigenspace_.truncation_bound_`` bounds how much lower that leaves
            the kept eigenvalues.
        reject_rate: None (no rejection), or the fraction in (0, 1) of known views one
            accepts to reject as unknown: ``fit`` calibrates the recognizer's thresholds
            on views synthesized at ``reject_poses`` (:func:`calibrate_rejection`); 0.05
            is a good start. Needs ``synth``.
        reject_score: the rejection score, ``"difs"`` (distance to the nearest gallery
            view; the best on COIL-20), ``"dffs"`` or ``"both"``.
        reject_poses: the held-out views' poses, where known objects are to be met (the
            threshold grows with how far they lie past the gallery): ``"around-seeds"``
            (default), every 2.5° from 45° before each object's first seed view to 45°
            past its last (25° past the default gallery on both sides), or (start, stop,
            step) in degrees relative to the first seed view; gallery poses are left out.
            Round the circle the held-out views are the midpoints between consecutive
            gallery views (only ``"around-seeds"`` is taken).
        workers: threads or processes that synthesize the objects' galleries, a few
            objects each at a time with their flows in shared calls (the same views as
            one at a time); 0 (the default) synthesizes in the calling thread. Threads run
            torch under the caller's intra-op thread setting: run them under
            :func:`~torch_eigview.scale.thread_policy.threads` ``(1)``, as the commands do.
        worker_kind: ``"thread"`` (the default: torch's kernels release the GIL) or
            ``"process"`` (spawned processes, one torch thread each: for flows that hold
            the GIL, ``"ilk"`` and ``"tvl1-skimage"``).

    Attributes:
        eigenspace_, projection_, recognizer_: the fitted eigenspace, its frozen layer and
            the nearest-neighbour recognizer over the gallery.
        gallery_labels_, gallery_poses_: (P,) labels and poses (degrees in (−180, 180]).
        label_names_: the objects' names when ``fit`` was given names as labels, else None.
        image_shape_: (C, H, W) of the views.
        elevations_: per object, its seed pairs' camera elevations (degrees).
        seconds_: time spent in ``"correspondence"``, ``"synthesis"`` and ``"eigen"``.
        n_calibration_views_: the held-out views the rejection was calibrated on (0
            without ``reject_rate``).
        reject_rate_estimate_: the calibration's own estimate of the fraction of known
            views it rejects: each object's held-out views judged by the thresholds set
            on the other objects' (:func:`~torch_eigview.method.rejection.estimate_reject_rate`);
            None without ``reject_rate`` or with one object.
        preprocessing_, seed_azimuths_: after :meth:`fit_manifest`, what every image file
            goes through (:class:`~torch_eigview.io.preprocessing.Preprocessing`, used by
            :meth:`predict_files` and recorded by :meth:`save`) and the seed azimuths;
            None after :meth:`fit` or :meth:`fit_blocks` on tensors.

    Example:
        >>> seeds = torch.rand(2, 2, 1, 16, 16)  # 2 objects, seed views at 0 and 10 degrees
        >>> est = FewViewEigenspace(3, synth=None).fit(seeds, [0.0, 10.0], labels=[4, 7])
        >>> est.predict(seeds[1]).labels.tolist()
        [7, 7]
    """

    preprocessing_: Preprocessing | None
    seed_azimuths_: list[float] | None

    def __init__(
        self,
        n_components: int | float | None = 15,
        *,
        synth: tuple[float, float, float] | str | Circle | None = AROUND_SEEDS,
        options: SynthesisOptions | None = None,
        unit_norm: bool = True,
        kernel: str | None = None,
        gamma: float | str | None = None,
        degree: int = 3,
        synth_follows_seeds: bool = True,
        max_views: int = 4096,
        reject_rate: float | None = None,
        reject_score: str = "difs",
        reject_poses: tuple[float, float, float] | str = AROUND_SEEDS,
        workers: int = 0,
        worker_kind: str = "thread",
        max_rank: int = 512,
    ) -> None:
        self.n_components = n_components
        self.synth = synth
        self.options = options
        self.unit_norm = unit_norm
        self.kernel = kernel
        self.gamma = gamma
        self.degree = degree
        self.synth_follows_seeds = synth_follows_seeds
        self.max_views = max_views
        self.reject_rate = reject_rate
        self.reject_score = reject_score
        self.reject_poses = reject_poses
        self.workers = workers
        self.worker_kind = worker_kind
        self.max_rank = max_rank

    def __repr__(self) -> str:
        return f"FewViewEigenspace(n_components={self.n_components!r}, synth={self.synth!r}, kernel={self.kernel!r})"

    def _params(self) -> Params:
        n_components = resolve_components(self.n_components)
        if self.options is not None and not isinstance(self.options, SynthesisOptions):
            raise TypeError(f"options must be a SynthesisOptions or None, got {type(self.options).__name__}")
        for name in ("unit_norm", "synth_follows_seeds"):
            if not isinstance(getattr(self, name), bool):
                raise TypeError(f"{name} must be a bool, got {getattr(self, name)!r}")
        if self.kernel is not None:
            # Validates the kernel, gamma and degree.
            space = KernelEigenspace(n_components, kernel=self.kernel, gamma=self.gamma, degree=self.degree)
            space._validate_params()  # stored as given: checked here, before any synthesis
        elif self.gamma is not None:
            raise ValueError(f"gamma={self.gamma!r} needs a kernel (kernel is None)")
        elif self.degree != 3:
            raise ValueError(f"degree={self.degree!r} needs kernel='poly' (kernel is None)")
        return Params(
            n_components,
            check_synth(self.synth, around=True),
            self.options or SynthesisOptions(),
            self.unit_norm,
            self.kernel,
            self.gamma,
            self.synth_follows_seeds,
            check_int(self.max_views, "max_views", 1),
            check_int(self.workers, "workers", minimum=0),
            check_choice(self.worker_kind, "worker_kind", KINDS),
            self._max_rank(n_components),
            degree=self.degree,
        )

    def _max_rank(self, n_components: int | float) -> int:
        rank = check_int(self.max_rank, "max_rank", minimum=1)
        if isinstance(n_components, int) and rank < n_components:
            raise ValueError(f"max_rank={rank} must be at least n_components={n_components}")
        return rank

    def _reject_params(self, synth: object) -> tuple[float, str, tuple[float, float, float] | str] | None:
        if self.reject_rate is None:
            return None
        rate = check_reject_rate(self.reject_rate)
        score = check_choice(self.reject_score, "reject_score", REJECT_SCORES)
        poses = check_synth(self.reject_poses, "reject_poses", around=True)
        if poses is None or isinstance(poses, Circle):
            raise ValueError(
                f"reject_poses must be (start, stop, step) in degrees or {AROUND_SEEDS!r}, got {self.reject_poses!r}"
            )
        if synth is None:
            raise ValueError(
                f"reject_rate={rate} calibrates on synthesized views: it needs synth, got synth=None "
                "(or calibrate on held-out views with calibrate_rejection)"
            )
        if isinstance(synth, Circle) and poses != AROUND_SEEDS:
            raise ValueError(
                f"reject_poses={poses!r} cannot be placed round the full circle: its held-out views are the "
                f"midpoints between gallery views; leave reject_poses at {AROUND_SEEDS!r}"
            )
        return rate, score, poses

    # ------------------------------------------------------------------ fitting
    def fit(
        self,
        seeds: object,
        seed_angles: object,
        labels: object = None,
        *,
        masks: object = None,
        progress: Callable[[Iterable[Any]], Iterable[Any]] | None = None,
    ) -> FewViewEigenspace:
        """Synthesizes every object's gallery from its seed views and fits on all of them.

        Memory: the gallery views twice (P × N, and their unit-norm copy) plus the P×P
        Gram matrix, P the gallery's views (per object, 51 for two seeds 10° apart at
        the default ``synth``: −20..30); :meth:`fit_blocks` fits without holding them.

        Args:
            seeds: (O, V, C, H, W) seed views of O objects, or a sequence of O
                (V_o, C, H, W) tensors (float32/float64).
            seed_angles: the seed views' angles in degrees (absolute: the gallery poses
                are these plus the synthesized offsets): V numbers shared by every object,
                or one sequence per object. With ``synth``, V_o >= 2 and the angles are
                equally spaced (either sign) or increasing (Sec. 4.1's α_n); round the
                circle, M >= 3 angles 360/M apart.
            labels: O labels, default 0 … O − 1: ints, or names (strings), which become
                ``label_names_`` (the labels are then 0 … O − 1).
            masks: optional foreground masks of the seed views, True on the object: an
                (O, V, H, W) bool tensor or a sequence of O (V_o, H, W) ones (an entry
                may be None). They replace the brightness threshold of synthesis
                (silhouette-aware sampling, size normalization, the automatic elevation);
                the seeds' background should already be one constant (e.g.
                :class:`~torch_eigview.datasets.background.BackgroundModel`'s ``apply``).
            progress: optional wrapper over the objects' labels (names), advanced as each
                object's gallery is ready (e.g. ``tqdm.tqdm``).

        Returns:
            self, fitted (see the class's attributes).

        Raises:
            TypeError, ValueError: a bad hyperparameter or argument; the message names it.
        """
        params = self._params()
        reject = self._reject_params(params.synth)
        objects = check_seeds(seeds)
        circle = isinstance(params.synth, Circle)
        angles = check_angles(seed_angles, objects, synthesis=params.synth is not None and not circle)
        if circle:
            check_circle_angles(angles)
        label_list, names = check_labels(labels, len(objects))
        seed_masks = check_seed_masks(masks, objects)
        if params.synth is not None:
            warn_unnormalized_seeds(objects, params.options)
        self.elevations_: list[list[float]] = []
        self.seconds_: dict[str, float] = {"correspondence": 0.0, "synthesis": 0.0, "eigen": 0.0}
        held_poses = None if reject is None else reject[2]
        plans = None if params.synth is None else self._jobs(params, objects, angles, seed_masks, held_poses)
        sizes = self._gallery_sizes(params, objects, plans, held_poses is not None)
        if objects[0].device.type == "cpu":
            estimate = fit_estimate(
                objects=len(objects),
                views=max(g for g, _ in sizes),
                held_out=max(h for _, h in sizes),
                image_shape=(objects[0].shape[1], objects[0].shape[2], objects[0].shape[3]),
                itemsize=objects[0].element_size(),
                components=params.n_components,
                max_views=params.max_views,
                max_rank=params.max_rank,
                kernel=params.kernel is not None,
                workers=params.workers,
            )
            check_memory(estimate, MEMORY_REMEDIES)
        gallery = GalleryFit(params, sum(g for g, _ in sizes), len(objects))
        # In a process group each rank synthesizes its own share of the objects, and the
        # shares' galleries are gathered in rank order before the model (scale/ranks.py).
        shard = object_shard(len(objects))
        mine = [objects[i] for i in shard], [angles[i] for i in shard], [label_list[i] for i in shard]
        ticks = [(names if names is not None else label_list)[i] for i in shard]
        for block, label, block_poses, held in self._galleries(
            params,
            *mine,
            None if plans is None else [plans[i] for i in shard],
            held_poses,
            progress(ticks) if progress else ticks,
        ):
            t0 = time.perf_counter()
            gallery.add(block, label, block_poses, held)
            self.seconds_["eigen"] += time.perf_counter() - t0
        t0 = time.perf_counter()
        if len(shard) < len(objects):
            gallery.gather()
            self.elevations_ = [e for part in gather_in_rank_order(self.elevations_) for e in part]
        space, projection, recognizer = gallery.finish(names)
        assert gallery.image_shape is not None
        self._set_fitted(space, projection, recognizer, gallery.image_shape)
        self.seconds_["eigen"] += time.perf_counter() - t0
        self.n_calibration_views_ = sum(v.shape[0] for v in gallery.held_out)
        self.reject_rate_estimate_: float | None = None
        if reject is not None:
            with torch.no_grad():
                held_views = torch.cat(gallery.held_out)
                calibrate_rejection(self.recognizer_, held_views, reject[0], reject[1])
                if len(gallery.held_out) > 1:  # each object's views by the others' thresholds
                    groups = torch.arange(len(gallery.held_out)).repeat_interleave(
                        torch.tensor([v.shape[0] for v in gallery.held_out])
                    )
                    self.reject_rate_estimate_ = estimate_reject_rate(
                        self.recognizer_, held_views, groups, reject[0], reject[1]
                    )
        return self

    def fit_manifest(
        self,
        views: object,
        seeds: Sequence[float] | None = None,
        *,
        size: Sequence[int] | None = None,
        channels: int | None = None,
        background: str | Sequence[float] | None = None,
        tolerance: float | None = None,
        progress: Callable[[Iterable[Any]], Iterable[Any]] | None = None,
    ) -> FewViewEigenspace:
        """Fits on every object of a manifest from its views at the seed azimuths, as ``eigview fit`` does.

        The views are read by :func:`~torch_eigview.datasets.seed_views.read_seed_views`
        (the command's own path), which settles the preprocessing every later image needs:
        :meth:`predict_files` applies it and :meth:`save` records it, so that ``eigview
        predict --model`` and ``eigview evaluate`` read images the same way.

        Args:
            views: a :class:`~torch_eigview.datasets.ViewManifest`, a
                :class:`~torch_eigview.datasets.ViewDataset` (its size and channels), or
                :class:`~torch_eigview.datasets.seed_views.SeedViews` already read (then
                ``seeds`` and the reading options are not given).
            seeds: two or more seed azimuths in degrees (round the circle, with
                ``synth="circle"``: M >= 3 azimuths 360/M apart); the object names become
                ``label_names_``.
            size, channels, background, tolerance: as
                :func:`~torch_eigview.datasets.seed_views.read_seed_views` takes them:
                ``(H, W)``; 1 or 3; ``"keep"``, ``"auto"``, a colour in [0, 1] or None
                (``"auto"`` where the views have masks, else ``"keep"``); a colour distance.
            progress: as :meth:`fit`'s.

        Returns:
            self, fitted, with ``preprocessing_`` and ``seed_azimuths_`` set.

        Raises:
            TypeError, ValueError: a bad argument (named), or a view that cannot be read.
        """
        from torch_eigview.datasets.seed_views import SeedViews, read_seed_views

        if isinstance(views, SeedViews):
            given = {"seeds": seeds, "size": size, "channels": channels, "background": background}
            extra = [name for name, value in {**given, "tolerance": tolerance}.items() if value is not None]
            if extra:
                raise ValueError(
                    f"{', '.join(extra)} cannot be given with SeedViews: they were read with theirs"
                )
            read = views
        else:
            if seeds is None:
                raise TypeError("fit_manifest needs seeds, the seed azimuths in degrees (e.g. [0, 10])")
            read = read_seed_views(
                views,  # type: ignore[arg-type]  # read_seed_views names a wrong type
                seeds,
                size=size,
                channels=channels,
                background=background,
                tolerance=tolerance,
            )
        self.fit(read.views, read.angles, labels=read.objects, masks=read.masks, progress=progress)
        self.preprocessing_ = replace(read.preprocessing, unit_norm=bool(self.unit_norm))
        self.seed_azimuths_ = list(read.azimuths)
        return self

    @staticmethod
    def _gallery_sizes(
        params: Params,
        objects: list[torch.Tensor],
        plans: list[tuple[ObjectJob, int, list[float]]] | None,
        held: bool,
    ) -> list[tuple[int, int]]:
        """Per object its gallery views and its held-out views, before any is made."""
        if plans is None:
            return [(v.shape[0], 0) for v in objects]
        sizes = []
        for job, n, _ in plans:
            if n >= 0:
                sizes.append((n, len(job.thetas or []) - n))
            else:  # the full circle: every pair's sector, and as many midpoints held out
                assert isinstance(params.synth, Circle)
                m = job.seeds.shape[0]
                count = m * len(circle_thetas(m, params.synth.step, params.synth.overlap))
                sizes.append((count, count if held else 0))
        return sizes

    def _jobs(
        self,
        params: Params,
        objects: list[torch.Tensor],
        angles: list[list[float]],
        masks: list[torch.Tensor | None],
        held_poses: tuple[float, float, float] | str | None,
    ) -> list[tuple[ObjectJob, int, list[float]]]:
        """Per object its synthesis job, its number of gallery views and their angles from
        its first seed (the job's views past those are held out; the full circle's are
        interleaved, see :meth:`_split`); every angle checked before any view is made."""
        plans: list[tuple[ObjectJob, int, list[float]]] = []
        for views, seed_angles, mask in zip(objects, angles, masks, strict=True):
            if isinstance(params.synth, Circle):
                plans.append((ObjectJob(views, 360.0 / views.shape[0], None, mask), -1, []))
                continue
            if views.shape[0] < 2:
                raise ValueError(
                    f"synthesis needs V >= 2 seed views per object, got V={views.shape[0]} (or synth=None)"
                )
            steps = seed_steps(seed_angles)
            alpha: float | list[float] = steps[0] if len(set(steps)) == 1 else steps
            thetas = params.thetas(steps)
            poses_o = held_out_range(steps) if isinstance(held_poses, str) else held_poses  # AROUND_SEEDS
            held = [] if poses_o is None else off_gallery(poses_o, thetas, "reject_poses")
            check_reach(seed_angles, thetas, held)
            plans.append((ObjectJob(views, alpha, thetas + held, mask), len(thetas), thetas))
        return plans

    def _galleries(
        self,
        params: Params,
        objects: list[torch.Tensor],
        angles: list[list[float]],
        labels: list[int],
        plans: list[tuple[ObjectJob, int, list[float]]] | None,
        held_poses: tuple[float, float, float] | str | None,
        ticks: Iterable[Hashable],
    ) -> Iterator[tuple[torch.Tensor, int, list[float], torch.Tensor | None]]:
        """Per object its gallery views, label and poses (degrees, unwrapped), synthesized
        over ``params.workers`` from ``plans`` (:meth:`_jobs`), and its views synthesized at
        ``held_poses`` (start, stop, step, or :data:`AROUND_SEEDS`) that are not gallery
        poses (in the same call, from the same geometry; None without); appends its
        elevations to ``elevations_`` and its times to ``seconds_``."""
        if plans is None:
            for views, seed_angles, label, _ in zip(objects, angles, labels, ticks, strict=True):
                yield views, label, seed_angles, None
            return
        circle = params.synth if isinstance(params.synth, Circle) else Circle()
        if isinstance(params.synth, Circle) and held_poses is not None:
            circle = Circle(circle.step / 2, circle.overlap)  # the midpoints are held out
        workers = params.workers if objects[0].device.type == "cpu" else 0
        per_view = objects[0][0].numel() * objects[0].element_size()
        counts = [
            len(job.thetas)
            if job.thetas is not None
            else job.seeds.shape[0] * len(circle_thetas(job.seeds.shape[0], circle.step, circle.overlap))
            for job, _, _ in plans
        ]
        results = object_galleries(
            (job for job, _, _ in plans),
            ticks,
            params.options,
            circle,
            workers=workers,
            kind=params.worker_kind,
            group=group_size(len(objects), workers, max(counts) * per_view),
        )
        for (_, out), (_, n, thetas), seed_angles, label in zip(results, plans, angles, labels, strict=True):
            for key, value in out.seconds.items():
                self.seconds_[key] = self.seconds_.get(key, 0.0) + value
            self.elevations_.append(out.elevations)
            gallery, gallery_thetas, held = self._split(out, n, thetas, held_poses is not None, circle.step)
            yield gallery, label, [seed_angles[0] + t for t in gallery_thetas], held

    @staticmethod
    def _split(
        out: SynthesizedViews, n: int, thetas: list[float], held: bool, step: float
    ) -> tuple[torch.Tensor, list[float], torch.Tensor]:
        """An object's gallery views, their angles and its held-out views: the first ``n``
        and the rest, or round the circle (``n`` < 0, synthesized every ``step`` degrees)
        every view, or with ``held`` the views an even number of steps from their pair's
        seed and the midpoints between them."""
        if n >= 0:
            return out.views[:n], thetas, out.views[n:]
        if not held:
            return out.views, out.thetas.tolist(), out.views[:0]
        alpha = 360.0 / (int(out.pairs.max()) + 1)
        mid = ((out.thetas - out.pairs * alpha) / step).round().long() % 2 == 1
        return out.views[~mid], out.thetas[~mid].tolist(), out.views[mid]

    def _set_fitted(
        self,
        space: Eigenspace | KernelEigenspace | StreamingEigenspace | IncrementalEigenspace,
        projection: EigenProjection | KernelProjection,
        recognizer: NearestNeighborRecognizer,
        image_shape: tuple[int, int, int],
    ) -> None:
        self.eigenspace_ = space
        self.projection_ = projection
        self.recognizer_ = recognizer
        self.gallery_labels_ = recognizer.labels
        self.gallery_poses_ = recognizer.poses
        self.label_names_ = recognizer.label_names
        self.image_shape_ = image_shape
        self.preprocessing_ = None  # fit_manifest sets them
        self.seed_azimuths_ = None

    def fit_blocks(self, blocks: object) -> FewViewEigenspace:
        """Fits on gallery views that arrive block by block, never all in memory.

        The eigenspace is a :class:`~torch_eigview.decomposition.streaming.StreamingEigenspace`
        (exact: equal to :meth:`fit`'s on the same views up to float rounding, or to the
        subspace solver's tolerance where :meth:`fit`'s eigenspace takes it: P and N both
        at least 4096 views and values); a last
        pass projects the blocks into the gallery. Nothing is synthesized: the blocks
        are the gallery (real views, or views synthesized beforehand). Linear eigenspace
        only (``kernel=None``).

        Memory: the P×P float64 Gram matrix (the N×N scatter when N <= P), up to
        ``max_views`` views at once, and the (P, k) gallery coordinates. Passes over
        ``blocks``: 4 when P <= ``max_views`` (mean, Gram, components, gallery), one more
        per further ``max_views`` views.

        Args:
            blocks: a ``DataLoader`` that does not shuffle, any re-iterable (a list) or a
                callable returning a fresh iterable: every pass must yield the same views
                in the same order. A one-shot iterator (a generator) is collected in
                memory first. Each item: (B, C, H, W) views, or ``(views, labels)`` or
                ``(views, labels, poses)`` with (B,) int labels and poses in degrees; a bare
                tensor's views take the block's index as label and pose 0. Or a dict as a
                :class:`~torch_eigview.datasets.ViewDataset` yields it (one view; so the
                dataset itself is a valid ``blocks``) or as a ``DataLoader`` over one
                collates it: ``image`` the views, ``object`` the names (numbered in order
                of first appearance; they become ``label_names_``), ``azimuth`` the poses.
                The ``mask`` is not read: give the dataset a ``background`` to apply it.

        Returns:
            self, fitted as by :meth:`fit` (``elevations_`` empty).
        """
        params = self._params()
        if params.kernel is not None:
            raise ValueError(
                f"fit_blocks fits the linear eigenspace only: kernel must be None, got {params.kernel!r}"
            )
        if self.reject_rate is not None:
            raise ValueError(
                f"fit_blocks synthesizes nothing to calibrate reject_rate={self.reject_rate!r} on: set "
                "reject_rate=None and call calibrate_rejection(est.recognizer_, held_out_views, rate)"
            )
        source = block_source(blocks)

        def prepared() -> Iterator[torch.Tensor]:
            for i, item in enumerate(source()):
                views = block_item(item, i)[0]
                yield unit_rows(views).view(views.shape) if params.unit_norm else views

        with torch.no_grad():
            space = StreamingEigenspace(params.n_components, max_views=params.max_views).fit(prepared)
            assert space.image_shape_ is not None  # the blocks are (B, C, H, W)
            image_shape = space.image_shape_
            projection = space.to_module(unit_norm=params.unit_norm, image_shape=image_shape)
            codes, labels, poses = [], [], []
            names: dict[str, int] = {}  # object name → label, for dict blocks (ViewDataset items)
            dicts = set()
            for i, item in enumerate(source()):
                views, block_labels, block_poses = block_item(item, i, names)
                dicts.add(isinstance(item, Mapping))
                codes.append(projection(views))
                labels.append(block_labels)
                poses.append(block_poses.to(views.dtype))
            if names and len(dicts) > 1:
                raise ValueError(
                    "blocks mixes ViewDataset items (dicts, labelled by object name) with tensors or tuples "
                    "(labelled by int): give every block one way"
                )
            recognizer = NearestNeighborRecognizer(
                projection,
                torch.cat(codes),
                torch.cat(labels),
                wrap_degrees(torch.cat(poses)),
                label_names=list(names) or None,
            )
        self.elevations_ = []
        self.seconds_ = {}
        self.n_calibration_views_ = 0
        self.reject_rate_estimate_ = None
        self._set_fitted(space, projection, recognizer, image_shape)
        return self

    # ------------------------------------------------------------------ inference
    def _fitted(self, what: str) -> NearestNeighborRecognizer:
        if not hasattr(self, "recognizer_"):
            raise NotFittedError(
                f"this FewViewEigenspace is not fitted yet: call fit or fit_blocks before {what}"
            )
        return self.recognizer_

    def predict(self, views: torch.Tensor, *, reject: bool = False) -> Recognition:
        """Recognizes (B, C, H, W) or (B, N) views: labels, poses, distances, gallery indices,
        each (B,), and with ``reject`` (fitted with ``reject_rate``) ``known``."""
        return self._fitted("predict").predict(views, reject=reject)

    def transform(self, views: torch.Tensor) -> torch.Tensor:
        """(B, C, H, W) or (B, N) views → (B, k) eigenspace coordinates."""
        projection = self._fitted("transform").projection
        with torch.no_grad():
            return projection(views)

    def to_module(self, unit_norm: bool | None = None) -> EigenProjection | KernelProjection:
        """A copy of the fitted layer; ``unit_norm`` (None, the default: as fitted, this
        estimator's ``unit_norm``) sets whether it scales each view to unit L2 norm first
        (False: the caller's views must be unit-norm already)."""
        self._fitted("to_module")
        unit = self.projection_.unit_norm if unit_norm is None else unit_norm
        if isinstance(self.eigenspace_, KernelEigenspace):
            return self.eigenspace_.to_module(unit_norm=unit)
        return self.eigenspace_.to_module(unit_norm=unit, image_shape=self.image_shape_)

    # ------------------------------------------------------------------ files
    def _preprocessing(self, what: str) -> Preprocessing:
        """``preprocessing_``, or for a fit on tensors the images' own size and channels as read."""
        self._fitted(what)
        if self.preprocessing_ is not None:
            return self.preprocessing_
        c, h, w = self.image_shape_
        if c not in (1, 3):
            raise ValueError(
                f"{what} reads gray or RGB image files; this model takes (C, H, W)={self.image_shape_}: "
                "fit it with fit_manifest, or read the images yourself"
            )
        return Preprocessing((h, w), c, unit_norm=bool(self.projection_.unit_norm))

    def predict_files(
        self, paths: str | os.PathLike[str] | Sequence[str | os.PathLike[str]], *, reject: bool = False
    ) -> Recognition:
        """Recognizes image files, each read through the model's preprocessing
        (:func:`~torch_eigview.datasets.seed_views.read_images`; ``preprocessing_`` after
        :meth:`fit_manifest`, else the fitted size and channels with the pixels as read), as
        ``eigview predict --model`` does with the saved model.

        Returns:
            As :meth:`predict`: (B,) labels (``label_names_[label]`` is the object's name),
            poses, distances, gallery indices and, with ``reject``, ``known``.
        """
        from torch_eigview.datasets.seed_views import read_images

        recognizer = self._fitted("predict_files")
        images = read_images(paths, self._preprocessing("predict_files"), dtype=recognizer.codes.dtype)
        return self.predict(images.to(recognizer.codes.device), reject=reject)

    def save(self, path: str | os.PathLike[str], metadata: Mapping[str, Any] | None = None) -> None:
        """Writes the fitted model to one file in ``eigview fit``'s format: ``eigview predict
        --model``, ``evaluate`` and ``export`` take it, and :func:`torch_eigview.io.load_model`
        reads it back.

        The file holds the recognizer (checksummed, written atomically:
        :func:`~torch_eigview.io.checkpoint.save_recognizer`) and the preprocessing
        (:meth:`fit_manifest`'s, else the fitted size and channels with the pixels kept as
        read), the label names and the seed azimuths.

        Args:
            path: the model file.
            metadata: further JSON values recorded with it (they override the defaults).

        Raises:
            NotFittedError: not fitted yet.
            TypeError: a kernel eigenspace, which this file format does not hold, or
                non-JSON ``metadata``.
            ValueError: ``path`` cannot be written.
        """
        from torch_eigview.io.checkpoint import save_recognizer

        recognizer = self._fitted("save")
        if metadata is not None and not isinstance(metadata, Mapping):
            raise TypeError(
                f"metadata must be a mapping of JSON values or None, got {type(metadata).__name__}"
            )
        meta: dict[str, Any] = {
            "command": "python",
            "preprocessing": self._preprocessing("save").to_json(),
            "n_train_views": int(recognizer.codes.shape[0]),
            "reject_rate": self.reject_rate,
        }
        if self.seed_azimuths_ is not None:
            meta["seed_azimuths"] = list(self.seed_azimuths_)  # evaluate --exclude-seeds reads them
        meta.update(metadata or {})
        # By keyword: the call does not depend on save_recognizer's argument order.
        save_recognizer(recognizer=recognizer, path=path, metadata=meta)
