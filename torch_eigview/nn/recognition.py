"""Recognition by nearest neighbour in the eigenspace (Sec. 4.2).

Every gallery view (each object's synthesized views) is projected once; a test image is
projected and takes the label and pose of the nearest gallery point. ``predict(x,
interpolate_pose=True)`` refines the pose on the appearance manifold, as Murase and Nayar
do: each object's gallery codes in pose order form a curve, taken piecewise linear
between consecutive views; the test code is projected onto the two segments that meet at
its nearest view, and the pose is interpolated along the closer one.

With rejection thresholds set (:meth:`NearestNeighborRecognizer.set_rejection`),
``predict(x, reject=True)`` also says which views are of known objects
(:mod:`torch_eigview.nn.rejection`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import torch
from torch import nn

from torch_eigview.check import check_finite, check_float_tensor, check_ndim
from torch_eigview.nn.kernel_projection import KernelProjection
from torch_eigview.nn.projection import EigenProjection
from torch_eigview.nn.rejection import NOT_CALIBRATED, check_reject_thresholds, dffs_of, thresholded_score

__all__ = ["NearestNeighborRecognizer", "Recognition", "pose_neighbours"]


@dataclass(frozen=True)
class Recognition:
    """What the recognizer says about B test images.

    Attributes:
        labels: (B,) int64 object label of the nearest gallery view.
        poses: (B,) pose of that view in degrees.
        distances: (B,) Euclidean distance to it in the eigenspace.
        indices: (B,) int64 index of that view in the gallery.
        known: (B,) bool, True where the view passed the rejection thresholds (its label
            stands), False for a view taken to be of an unknown object; None when
            rejection was not asked for.
    """

    labels: torch.Tensor
    poses: torch.Tensor
    distances: torch.Tensor
    indices: torch.Tensor
    known: torch.Tensor | None = None


class NearestNeighborRecognizer(nn.Module):
    """A frozen eigenspace projection with a gallery of labelled, posed points.

    ``forward`` returns tensors only (label, pose, distance), so the whole recognizer
    exports to ONNX as Sub/MatMul for the projection and MatMul/ReduceMin/ArgMin/Gather for
    the search; squared distances are expanded as ``|z|² - 2 z·g + |g|²``.

    Args:
        projection: the frozen :class:`EigenProjection` or :class:`KernelProjection`
            (any ``nn.Module`` with an int ``n_components`` k and tensor buffers).
        codes: (G, k) gallery points in the eigenspace.
        labels: (G,) int64 object labels.
        poses: (G,) poses in degrees.
        label_names: optional names, one per distinct label value, in sorted label order.
        reject_thresholds: optional (2,) rejection thresholds ``(t_dffs, t_difs)``, see
            :meth:`set_rejection`; kept in the ``reject_thresholds`` buffer, (0,) when None.

    Example:
        >>> proj = EigenProjection(torch.zeros(4), torch.eye(4)[:2])
        >>> rec = NearestNeighborRecognizer.from_views(proj, torch.eye(4)[:2], torch.tensor([3, 7]), torch.tensor([0.0, 5.0]))
        >>> rec.predict(torch.tensor([[0.0, 0.9, 0.0, 0.0]])).labels
        tensor([7])
    """

    codes: torch.Tensor
    labels: torch.Tensor
    poses: torch.Tensor
    codes_sqnorm: torch.Tensor
    pose_before: torch.Tensor
    pose_after: torch.Tensor
    reject_thresholds: torch.Tensor

    def __init__(
        self,
        projection: EigenProjection | KernelProjection,
        codes: torch.Tensor,
        labels: torch.Tensor,
        poses: torch.Tensor,
        label_names: list[str] | None = None,
        reject_thresholds: torch.Tensor | None = None,
    ) -> None:
        super().__init__()
        n_components = getattr(projection, "n_components", None)
        if not isinstance(projection, nn.Module) or not isinstance(n_components, int):
            raise TypeError(
                "projection must be an EigenProjection or a KernelProjection (an nn.Module with an int "
                f"n_components), got {type(projection).__name__}"
            )
        reference = next(projection.buffers(), codes)  # the projection's dtype and device
        check_float_tensor(codes, "codes")
        check_ndim(codes, "codes", (2,), "(G, k)")
        check_finite(codes, "codes")
        g, k = codes.shape
        if g == 0:
            raise ValueError("codes must hold at least one gallery view, got G=0")
        if k != projection.n_components:
            raise ValueError(
                f"codes must have shape (G, {projection.n_components}), got {tuple(codes.shape)}"
            )
        for tensor, name in ((labels, "labels"), (poses, "poses")):
            if not isinstance(tensor, torch.Tensor):
                raise TypeError(f"{name} must be a torch.Tensor, got {type(tensor).__name__}")
        if tuple(labels.shape) != (g,) or labels.is_floating_point():
            raise ValueError(
                f"labels must be an integer tensor of shape ({g},), got {labels.dtype} {tuple(labels.shape)}"
            )
        if tuple(poses.shape) != (g,):
            raise ValueError(f"poses must have shape ({g},), got {tuple(poses.shape)}")
        check_finite(poses.to(torch.float64), "poses")
        n_distinct = int(labels.unique().numel())
        if label_names is not None and (
            isinstance(label_names, (str, bytes, Mapping)) or not isinstance(label_names, Sequence)
        ):
            # A str would be split into characters and a dict into its keys, silently.
            raise TypeError(
                f"label_names must be None or a list of names, one per distinct label, got "
                f"{type(label_names).__name__} {label_names!r:.80}"
            )
        if label_names is not None and len(label_names) != n_distinct:
            raise ValueError(
                f"label_names must name the {n_distinct} distinct labels, got {len(label_names)} names"
            )
        if label_names is not None and len({str(n) for n in label_names}) != len(label_names):
            # Two labels of one name would score one object's views as the other's.
            texts = [str(n) for n in label_names]
            repeated = sorted({n for n in texts if texts.count(n) > 1})
            raise ValueError(
                f"label_names must be distinct, one per label, got {repeated[:5]!r} more than once"
            )
        self.projection = projection
        self.label_names = None if label_names is None else [str(n) for n in label_names]
        codes = codes.detach().to(reference)
        self.register_buffer("codes", codes.clone())
        self.register_buffer("codes_sqnorm", codes.square().sum(dim=1))
        self.register_buffer("labels", labels.detach().to(torch.int64).clone())
        self.register_buffer("poses", poses.detach().to(reference).clone())
        # Derived from labels and poses, so not saved: a loaded recognizer rebuilds them.
        before, after = pose_neighbours(self.labels, self.poses)
        self.register_buffer("pose_before", before, persistent=False)
        self.register_buffer("pose_after", after, persistent=False)
        self.register_buffer("reject_thresholds", codes.new_empty(0))
        self.set_rejection(reject_thresholds)

    @classmethod
    def from_views(
        cls,
        projection: EigenProjection | KernelProjection,
        views: torch.Tensor,
        labels: torch.Tensor,
        poses: torch.Tensor,
        label_names: list[str] | None = None,
    ) -> NearestNeighborRecognizer:
        """Projects the gallery ``views`` (G, C, H, W) or (G, N) and builds the recognizer."""
        with torch.no_grad():
            codes = projection(views)
        return cls(projection, codes, labels, poses, label_names)

    @property
    def n_gallery(self) -> int:
        return self.codes.shape[0]

    @property
    def rejects(self) -> bool:
        """Whether rejection thresholds are set (``predict(..., reject=True)`` works)."""
        return self.reject_thresholds.numel() == 2

    def set_rejection(self, thresholds: torch.Tensor | None) -> None:
        """Sets (or with None clears) the thresholds a known view must stay within: (2,)
        ``(t_dffs, t_difs)``, the largest distance from feature space and to the nearest
        gallery view; each > 0, or ``inf`` to leave it out (see
        :func:`~torch_eigview.nn.rejection.check_reject_thresholds`, which raises)."""
        if thresholds is None:
            self.reject_thresholds = self.codes.new_empty(0)
            return
        check_reject_thresholds(thresholds, isinstance(self.projection, EigenProjection))
        self.reject_thresholds = thresholds.detach().to(self.codes).clone()

    def _load_from_state_dict(self, state_dict: dict[str, object], prefix: str, *args: object) -> None:
        # Calibrated or not, the buffer is (2,) or (0,); a recognizer built without
        # thresholds takes a saved one's.
        incoming = state_dict.get(prefix + "reject_thresholds")
        if isinstance(incoming, torch.Tensor) and tuple(incoming.shape) in {(0,), (2,)}:
            self.reject_thresholds = self.reject_thresholds.new_empty(incoming.shape)
        super()._load_from_state_dict(state_dict, prefix, *args)

    def extra_repr(self) -> str:
        n_labels = int(self.labels.unique().numel())
        text = f"gallery={self.n_gallery}, labels={n_labels}"
        if self.rejects:
            t_dffs, t_difs = self.reject_thresholds.tolist()
            text += f", reject_thresholds=(t_dffs={t_dffs:.4g}, t_difs={t_difs:.4g})"
        return text

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Recognizes a batch of views.

        Export-friendly by contract: no data-dependent check runs here (no ``.item()``, no
        branch on values), so NaN or infinite views give NaN distances rather than an
        error. Callers with untrusted data use :meth:`predict`, which checks.

        Args:
            x: (B, C, H, W) or (B, N) views (the projection's size; any floating dtype,
                cast to the projection's).

        Returns:
            ``(labels, poses, distances)``, each (B,).
        """
        labels, poses, distances, _ = self._search(x)
        return labels, poses, distances

    def _search(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        labels, poses, distances, index, _ = self._search_codes(x)
        return labels, poses, distances, index

    def _search_codes(
        self, x: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        z = self.projection(x)
        sq = z.square().sum(dim=1, keepdim=True) - 2 * z @ self.codes.T + self.codes_sqnorm
        best, index = sq.min(dim=1)
        return self.labels[index], self.poses[index], best.clamp_min(0).sqrt(), index, z

    def novelty_scores(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The two scores rejection compares with its thresholds, unchecked as ``forward``.

        Args:
            x: (B, C, H, W) or (B, N) views (the projection's size; any floating dtype,
                cast to the projection's).

        Returns:
            ``(dffs, difs)``, each (B,): the L2 distance of the prepared view (flattened,
            unit-norm if the layer is) from the eigenspace, ``sqrt(|v − mean|² − |z|²)``
            (NaN for a kernel projection, which has no linear feature space), and the
            distance to the nearest gallery view.
        """
        _, _, difs, _, z = self._search_codes(x)
        return dffs_of(self.projection, x, z), difs

    def rejection_scores(self, x: torch.Tensor) -> torch.Tensor:
        """(B, C, H, W) or (B, N) views → (B,) scores in units of the thresholds: a view is
        known when its score is <= 1 (:func:`~torch_eigview.nn.rejection.rejection_score`).
        Sweeping the limit 1 over the scores gives the ROC of the rejection.

        Raises:
            ValueError: no thresholds are set (``reject``).
        """
        if not self.rejects:
            raise ValueError(NOT_CALIBRATED)
        with torch.no_grad():
            _, _, difs, _, z = self._search_codes(x)
            return thresholded_score(self.projection, x, z, difs, self.reject_thresholds)

    def predict(
        self, x: torch.Tensor, *, interpolate_pose: bool = False, reject: bool = False
    ) -> Recognition:
        """Like ``forward``, as a :class:`Recognition` that also holds the gallery indices,
        with the checks ``forward`` leaves out: finite views, and for a unit-norm projection
        views whose L2 norm does not overflow the dtype (they would project to zeros).

        Args:
            x: (B, C, H, W) or (B, N) views (the projection's size; any floating dtype,
                cast to the projection's); B may be 0.
            interpolate_pose: refine each pose between the nearest gallery view and its
                neighbours in pose order (:meth:`interpolate_poses`); else the nearest
                view's pose, as ``forward`` (and the ONNX graph) give it.
            reject: fill ``known`` by the rejection thresholds (:meth:`rejection_scores`).

        Raises:
            TypeError: ``x`` is not a floating tensor (any floating dtype is cast to the
                layer's, as ``forward`` does), or ``interpolate_pose`` or ``reject`` is not a bool.
            ValueError: a bad shape, NaN or infinite values,
                non-finite distances (a damaged gallery), or ``reject`` without thresholds.
        """
        for flag, name in ((interpolate_pose, "interpolate_pose"), (reject, "reject")):
            if not isinstance(flag, bool):
                raise TypeError(f"{name} must be a bool, got {type(flag).__name__}")
        if reject and not self.rejects:
            raise ValueError(NOT_CALIBRATED)
        check_float_tensor(x, "x")
        check_ndim(x, "x", (2, 4), "(B, N) or (B, C, H, W)")
        if x.numel() and not bool(torch.isfinite(x.sum())):
            check_finite(x, "x")  # names the NaN or infinite values; else only the sum overflowed
        # A non-finite gallery point would win every search at distance 0 (-inf clamped):
        # (G, k) values, checked per call, cheap next to the projection.
        if not (bool(torch.isfinite(self.codes).all()) and bool(torch.isfinite(self.codes_sqnorm).all())):
            raise ValueError("the recognizer's gallery codes are not finite: the recognizer is damaged")
        with torch.no_grad():
            labels, poses, distances, index, z = self._search_codes(x)
        if not bool(torch.isfinite(distances).all()):
            raise ValueError(
                "the recognizer gave non-finite distances for finite views: the views' values (largest "
                f"magnitude {float(x.abs().max()):.3g}) overflow {self.codes.dtype} in the projection, or the "
                "gallery or projection is damaged"
            )
        with torch.no_grad():
            if interpolate_pose:
                poses = self.interpolate_poses(z, index)
            known = (
                thresholded_score(self.projection, x, z, distances, self.reject_thresholds) <= 1
                if reject
                else None
            )
        return Recognition(labels, poses, distances, index, known)

    def interpolate_poses(self, z: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
        """Poses interpolated on the appearance manifold (Murase and Nayar's pose estimate).

        Each object's gallery codes, in pose order, are joined by straight segments (closed
        into a loop when its poses go round the turntable, see :func:`pose_neighbours`).
        ``z`` is projected onto the two segments at its gallery view ``index`` (clamped to
        them); on the closer one, the fraction t in [0, 1] of the way to the neighbour
        gives the pose ``pose[index] + t · Δpose`` (Δpose taken the short way round).

        Args:
            z: (B, k) codes in the eigenspace.
            index: (B,) int64 gallery index of each code's nearest view.

        Returns:
            (B,) poses in degrees, of the gallery poses' dtype.
        """
        here = self.codes[index]
        offset = z.to(here.dtype) - here
        best_t = offset.new_zeros(index.shape)
        best_sq = offset.square().sum(dim=1)
        best_j = index
        for neighbour in (self.pose_before, self.pose_after):
            j = neighbour[index]
            step = self.codes[j] - here
            length_sq = step.square().sum(dim=1)
            t = ((offset * step).sum(dim=1) / length_sq.clamp_min(torch.finfo(step.dtype).tiny)).clamp(0, 1)
            sq = (offset - t[:, None] * step).square().sum(dim=1)
            closer = sq < best_sq
            best_t, best_sq, best_j = (
                torch.where(closer, t, best_t),
                torch.where(closer, sq, best_sq),
                torch.where(closer, j, best_j),
            )
        delta = self.poses[best_j] - self.poses[index]
        delta = delta - 360 * torch.round(delta / 360)
        return self.poses[index] + best_t * delta


def pose_neighbours(labels: torch.Tensor, poses: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Each gallery view's neighbours along its object's pose sequence.

    An object's views sorted by pose form a chain; it is closed into a loop when the gap
    from the last pose round to the first (through 360 degrees) is at most 1.5 times the
    largest gap inside the chain, i.e. when the views go round the turntable. A view at
    an open end is its own neighbour on that side.

    Args:
        labels: (G,) integer labels.
        poses: (G,) poses in degrees.

    Returns:
        ``(before, after)``: (G,) int64 gallery indices of the previous and next view.

    Example:
        >>> before, after = pose_neighbours(torch.tensor([0, 0, 0, 1, 1]),
        ...                                 torch.tensor([0.0, 120.0, 240.0, 10.0, 0.0]))
        >>> before.tolist(), after.tolist()
        ([2, 0, 1, 4, 4], [1, 2, 0, 3, 3])
    """
    labels, poses = labels.detach().cpu(), poses.detach().cpu().double()
    before = torch.arange(labels.numel())
    after = before.clone()
    for value in labels.unique():
        members = (labels == value).nonzero().flatten()
        order = members[torch.argsort(poses[members], stable=True)]
        if order.numel() < 2:
            continue
        before[order[1:]], after[order[:-1]] = order[:-1], order[1:]
        sorted_poses = poses[order]
        around = float(sorted_poses[0] + 360 - sorted_poses[-1])
        if around <= 1.5 * float(sorted_poses.diff().max()):
            before[order[0]], after[order[-1]] = order[-1], order[0]
    return before.to(labels.device), after.to(labels.device)
