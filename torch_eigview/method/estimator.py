"""The whole method as one estimator: seed views per object in, eigenspace and gallery out.

:class:`FewViewEigenspace` runs the recognition pipeline of the paper's experiments
(Sec. 4; :mod:`torch_eigview.evaluation.coil`) as a library object: per object, the
correspondences of its seed views and the views synthesized over a range of angles
(:func:`~torch_eigview.synthesis.synthesize_views`, Sec. 4.1 sectors for more than two
seeds); one eigenspace over every object's gallery views, each scaled to unit L2 norm
(Murase and Nayar's brightness normalization); the frozen projection layer; and the
nearest-neighbour recognizer over the gallery's coordinates (Sec. 4.2). With
``reject_rate``, ``fit`` also synthesizes views at poses held out from the gallery and
calibrates the recognizer's rejection of unknown objects on them
(:mod:`torch_eigview.method.rejection`).

It follows scikit-learn's conventions: hyperparameters are stored as given by
``__init__`` and validated by ``fit``, learned state ends in ``_``, ``fit`` returns self.
"""

from __future__ import annotations

from collections.abc import Iterator

import torch

from torch_eigview.check import check_choice, check_int
from torch_eigview.decomposition.eigenspace import Eigenspace
from torch_eigview.decomposition.kernel import KernelEigenspace
from torch_eigview.decomposition.streaming import StreamingEigenspace
from torch_eigview.errors import NotFittedError
from torch_eigview.geometry.angles import AROUND_SEEDS, held_out_range, off_gallery
from torch_eigview.method.inputs import (
    Params,
    block_item,
    block_source,
    check_angles,
    check_labels,
    check_seed_masks,
    check_seeds,
    check_synth,
    resolve_components,
    seed_steps,
    warn_unnormalized_seeds,
    wrap_degrees,
)
from torch_eigview.method.rejection import REJECT_SCORES, calibrate_rejection, check_reject_rate
from torch_eigview.nn.functional import unit_rows
from torch_eigview.nn.kernel_projection import KernelProjection
from torch_eigview.nn.projection import EigenProjection
from torch_eigview.nn.recognition import NearestNeighborRecognizer, Recognition
from torch_eigview.synthesis import SynthesisOptions, synthesize_views

__all__ = ["FewViewEigenspace"]

Gallery = tuple[torch.Tensor, int, list[float]]  # (T, C, H, W) views, label, T poses (degrees)


class FewViewEigenspace:
    """The paper's method from seed views to a fitted eigenspace and a recognizer.

    Args:
        n_components: eigenspace dimension k (int), energy fraction (float in (0, 1)), or
            None for every component above rounding (:data:`ALL_COMPONENTS`).
        synth: the synthesized angles: ``"around-seeds"`` (default,
            :data:`~torch_eigview.geometry.angles.AROUND_SEEDS`), every degree from 20°
            before each object's first seed view to 20° past its last; or (start, stop,
            step) in degrees relative to the first seed view, for two seeds (see
            ``synth_follows_seeds``; ``(-20, 20, 1)`` is the paper's protocol); None
            fits the seed views alone (the ``sparse`` baseline of the experiments). At
            most 3600 views per object (environment variable ``EIGVIEW_MAX_VIEWS``).
        options: :class:`~torch_eigview.synthesis.SynthesisOptions` (flow, elevation,
            extent, blend, silhouette, …); None for the defaults.
        unit_norm: scale every view to unit L2 norm before the eigenspace and in the layer.
        kernel: None for the linear eigenspace (the paper's), or a
            :class:`~torch_eigview.decomposition.kernel.KernelEigenspace` kernel name.
        gamma: the kernel's γ (a number, "median" for rbf, or None: 1/N).
        synth_follows_seeds: with more than two seeds, extend a (start, stop, step) ``synth`` on the seeds'
            side by the steps past the first pair (as ``CoilExperiment``).
        max_views: the most gallery views :meth:`fit_blocks` holds at once.
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

    Example:
        >>> seeds = torch.rand(2, 2, 1, 16, 16)  # 2 objects, seed views at 0 and 10 degrees
        >>> est = FewViewEigenspace(3, synth=None).fit(seeds, [0.0, 10.0], labels=[4, 7])
        >>> est.predict(seeds[1]).labels.tolist()
        [7, 7]
    """

    def __init__(
        self,
        n_components: int | float | None = 15,
        *,
        synth: tuple[float, float, float] | str | None = AROUND_SEEDS,
        options: SynthesisOptions | None = None,
        unit_norm: bool = True,
        kernel: str | None = None,
        gamma: float | str | None = None,
        synth_follows_seeds: bool = True,
        max_views: int = 4096,
        reject_rate: float | None = None,
        reject_score: str = "difs",
        reject_poses: tuple[float, float, float] | str = AROUND_SEEDS,
    ) -> None:
        self.n_components = n_components
        self.synth = synth
        self.options = options
        self.unit_norm = unit_norm
        self.kernel = kernel
        self.gamma = gamma
        self.synth_follows_seeds = synth_follows_seeds
        self.max_views = max_views
        self.reject_rate = reject_rate
        self.reject_score = reject_score
        self.reject_poses = reject_poses

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
            KernelEigenspace(n_components, kernel=self.kernel, gamma=self.gamma)  # validates both
        elif self.gamma is not None:
            raise ValueError(f"gamma={self.gamma!r} needs a kernel (kernel is None)")
        return Params(
            n_components,
            check_synth(self.synth, around=True),
            self.options or SynthesisOptions(),
            self.unit_norm,
            self.kernel,
            self.gamma,
            self.synth_follows_seeds,
            check_int(self.max_views, "max_views", 1),
        )

    def _reject_params(self, synth: object) -> tuple[float, str, tuple[float, float, float] | str] | None:
        if self.reject_rate is None:
            return None
        rate = check_reject_rate(self.reject_rate)
        score = check_choice(self.reject_score, "reject_score", REJECT_SCORES)
        poses = check_synth(self.reject_poses, "reject_poses", around=True)
        if poses is None:
            raise ValueError(
                f"reject_poses must be (start, stop, step) in degrees or {AROUND_SEEDS!r}, got None"
            )
        if synth is None:
            raise ValueError(
                f"reject_rate={rate} calibrates on synthesized views: it needs synth, got synth=None "
                "(or calibrate on held-out views with calibrate_rejection)"
            )
        return rate, score, poses

    # ------------------------------------------------------------------ fitting
    def fit(
        self, seeds: object, seed_angles: object, labels: object = None, *, masks: object = None
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
                equally spaced (either sign) or increasing (Sec. 4.1's α_n).
            labels: O int labels, default 0 … O − 1.
            masks: optional foreground masks of the seed views, True on the object: an
                (O, V, H, W) bool tensor or a sequence of O (V_o, H, W) ones (an entry
                may be None). They replace the brightness threshold of synthesis
                (silhouette-aware sampling, size normalization, the automatic elevation);
                the seeds' background should already be one constant (e.g.
                :class:`~torch_eigview.datasets.background.BackgroundModel`'s ``apply``).

        Returns:
            self, fitted: ``eigenspace_``, ``projection_``, ``recognizer_``,
            ``gallery_labels_`` (P,), ``gallery_poses_`` (P,) wrapped to (−180, 180],
            ``elevations_`` (per object, one per seed pair), ``image_shape_``.

        Raises:
            TypeError, ValueError: a bad hyperparameter or argument; the message names it.
        """
        params = self._params()
        reject = self._reject_params(params.synth)
        objects = check_seeds(seeds)
        angles = check_angles(seed_angles, objects, synthesis=params.synth is not None)
        names = check_labels(labels, len(objects))
        seed_masks = check_seed_masks(masks, objects)
        if params.synth is not None:
            warn_unnormalized_seeds(objects, params.options)
        self.elevations_: list[list[float]] = []
        views: list[torch.Tensor] = []
        label_list: list[int] = []
        poses: list[float] = []
        held_out: list[torch.Tensor] = []
        held_poses = None if reject is None else reject[2]
        for block, label, block_poses in self._galleries(
            params, objects, angles, names, seed_masks, held_poses, held_out
        ):
            views.append(block)
            label_list += [label] * len(block_poses)
            poses += block_poses
        x = torch.cat(views)
        with torch.no_grad():
            self._fit_gallery(params, x, torch.tensor(label_list), torch.tensor(poses, dtype=x.dtype))
        if reject is not None:
            calibrate_rejection(self.recognizer_, torch.cat(held_out), reject[0], reject[1])
        return self

    def _galleries(
        self,
        params: Params,
        objects: list[torch.Tensor],
        angles: list[list[float]],
        labels: list[int],
        masks: list[torch.Tensor | None],
        held_poses: tuple[float, float, float] | str | None = None,
        held_out: list[torch.Tensor] | None = None,
    ) -> Iterator[Gallery]:
        """Per object its gallery views, label and poses; appends its elevations to
        ``elevations_``, and to ``held_out`` its views synthesized at ``held_poses`` (start,
        stop, step, or :data:`AROUND_SEEDS`) that are not gallery poses (in the same call,
        from the same geometry)."""
        for views, seed_angles, label, mask in zip(objects, angles, labels, masks, strict=True):
            if params.synth is None:
                yield views, label, seed_angles
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
            out = synthesize_views(views, alpha, thetas + held, params.options, masks=mask)
            self.elevations_.append(out.elevations)
            if held_out is not None:
                held_out.append(out.views[len(thetas) :])
            yield out.views[: len(thetas)], label, [seed_angles[0] + t for t in thetas]

    def _fit_gallery(
        self, params: Params, x: torch.Tensor, labels: torch.Tensor, poses: torch.Tensor
    ) -> None:
        """The eigenspace of the gallery views x (P, C, H, W), the layer and the recognizer."""
        c, h, w = x.shape[1:]
        x_fit = unit_rows(x) if params.unit_norm else x.flatten(1)
        projection: EigenProjection | KernelProjection
        space: Eigenspace | KernelEigenspace
        if params.kernel is None:
            space = linear = Eigenspace(params.n_components).fit(x_fit)
            projection = linear.to_module(unit_norm=params.unit_norm, image_shape=(c, h, w))
        else:
            kspace = KernelEigenspace(params.n_components, kernel=params.kernel, gamma=params.gamma)
            space = kspace.fit(x_fit.reshape(-1, c, h, w))
            projection = kspace.to_module(unit_norm=params.unit_norm)
        recognizer = NearestNeighborRecognizer.from_views(projection, x, labels, wrap_degrees(poses))
        self._set_fitted(space, projection, recognizer, (c, h, w))

    def _set_fitted(
        self,
        space: Eigenspace | KernelEigenspace | StreamingEigenspace,
        projection: EigenProjection | KernelProjection,
        recognizer: NearestNeighborRecognizer,
        image_shape: tuple[int, int, int],
    ) -> None:
        self.eigenspace_ = space
        self.projection_ = projection
        self.recognizer_ = recognizer
        self.gallery_labels_ = recognizer.labels
        self.gallery_poses_ = recognizer.poses
        self.image_shape_ = image_shape

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
                tensor's views take the block's index as label and pose 0.

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
            for i, item in enumerate(source()):
                views, block_labels, block_poses = block_item(item, i)
                codes.append(projection(views))
                labels.append(block_labels)
                poses.append(block_poses.to(views.dtype))
            recognizer = NearestNeighborRecognizer(
                projection, torch.cat(codes), torch.cat(labels), wrap_degrees(torch.cat(poses))
            )
        self.elevations_ = []
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
        """A copy of the fitted layer; ``unit_norm`` (None: as fitted) sets whether it scales
        each view to unit L2 norm first (False: the caller's views must be unit-norm already)."""
        self._fitted("to_module")
        unit = self.projection_.unit_norm if unit_norm is None else unit_norm
        if isinstance(self.eigenspace_, KernelEigenspace):
            return self.eigenspace_.to_module(unit_norm=unit)
        return self.eigenspace_.to_module(unit_norm=unit, image_shape=self.image_shape_)
