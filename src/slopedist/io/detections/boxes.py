"""The box table: 2D boxes of many frames as numpy columns, and box checks and overlap.

Convention: boxes are ``(left, top, right, bottom)`` in pixels, origin top-left, rows downwards.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slopedist.core.errors import ConfigurationError, DataMismatchError

NO_TRACK = -1
"""Track id used when a box has no track id."""


BORDER_TOLERANCE_PX = 1.0
"""A box edge within this many pixels of the image border (or beyond it) is cut by it."""
ABSURD_COORDINATE_PX = 1e5
"""Without an image size, a box coordinate beyond ±this is absurd (``degenerate_box``)."""
ABSURD_IMAGE_SIZES = 10.0
"""With an image size, a coordinate more than this many image sizes outside it is absurd."""
MIN_BOX_SIZE_PX = 1.0
"""A box narrower or lower than this is ``degenerate_box`` (zero or sub-pixel size)."""

EDGES = ("left", "top", "right", "bottom")
"""Box edges in coordinate order; a ``cut`` label joins the cut ones with ``+``."""
_CUT_LABELS = np.array(
    ["+".join(e for i, e in enumerate(EDGES) if m & (1 << i)) for m in range(16)], dtype=object
)

_EDGE_BITS = np.array([1, 2, 4, 8])

DEFAULT_VEHICLE_CLASSES = ("Car", "Van", "Truck", "Bus", "Motorcycle", "Motorbike")
"""Class names scored as vehicles (case-insensitive). KITTI's ``Pedestrian``,
``Person_sitting``, ``Cyclist``, ``Tram``, ``Misc`` and ``DontCare`` are not: the ground
contact of a person, a rail vehicle or an unknown object is not a car's."""


def vehicle_class_names(names: Iterable[str]) -> tuple[str, ...]:
    """Class names to score as vehicles (``--vehicle-classes``), stripped, empty ones dropped.

    Raises:
        ConfigurationError: no name is left.
    """
    kept = tuple(n.strip() for n in names if n.strip())
    if not kept:
        raise ConfigurationError("give at least one vehicle class name")
    return kept


def box_problems(
    boxes: ArrayLike, image_size: tuple[int, int] | None = None
) -> NDArray[np.object_]:
    """Reason a box cannot be used, per box: ``""`` if fine, else (first that applies)
    ``non_finite_box``, ``inverted_box`` (right < left or bottom < top), ``degenerate_box``
    (width or height under :data:`MIN_BOX_SIZE_PX`, or absurd coordinates) or, when the image
    ``(width, height)`` in pixels is known, ``outside_image`` (no overlap with the image,
    whose pixels span ``[−0.5, width − 0.5] × [−0.5, height − 0.5]``)."""
    b = np.asarray(boxes, dtype=float).reshape(-1, 4)
    reasons = np.full(b.shape[0], "", dtype=object)
    if image_size is None:
        size = np.full(4, ABSURD_COORDINATE_PX)
        low, high = -size, size
    else:
        size = np.array(image_size * 2, dtype=float)
        low, high = -ABSURD_IMAGE_SIZES * size, (1 + ABSURD_IMAGE_SIZES) * size
    finite = np.isfinite(b).all(axis=1)
    sane = finite & ~((b < low) | (b > high)).any(axis=1)  # comparisons with NaN are False
    s = b if sane.all() else np.where(sane[:, None], b, 0.0)  # no overflow in differences
    w, h = s[:, 2] - s[:, 0], s[:, 3] - s[:, 1]
    inverted = sane & ((w < 0) | (h < 0))
    degenerate = finite & ~inverted & ((w < MIN_BOX_SIZE_PX) | (h < MIN_BOX_SIZE_PX))
    if image_size is not None:
        edge = np.array(image_size, dtype=float) - 0.5
        outside = (s[:, 2] <= -0.5) | (s[:, 3] <= -0.5)
        outside |= (s[:, 0] >= edge[0]) | (s[:, 1] >= edge[1])
        reasons[outside & sane & ~inverted & ~degenerate] = "outside_image"
    reasons[degenerate] = "degenerate_box"
    reasons[inverted] = "inverted_box"
    reasons[~finite] = "non_finite_box"
    return reasons


def border_cuts(
    boxes: ArrayLike, image_size: tuple[float, float] | None, tol_px: float = BORDER_TOLERANCE_PX
) -> NDArray[np.bool_]:
    """``(N, 4)`` flags: is the box's left, top, right, bottom edge cut by the image border
    (within ``tol_px`` of it or beyond)? All false without an image ``(width, height)``.

    Pixel centres are integer coordinates, so a box clipped to the image has ``left = 0`` and
    ``right = width − 1`` (KITTI's convention); ``right = width`` counts as cut too.
    """
    b = np.asarray(boxes, dtype=float).reshape(-1, 4)
    if image_size is None:
        return np.zeros(b.shape, dtype=bool)
    return cuts_at(b, border_cut_limits(image_size, tol_px))


def border_cut_limits(
    image_size: tuple[float, float], tol_px: float = BORDER_TOLERANCE_PX
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The limits ``(low, high)`` of :func:`border_cuts`, ``(4,)`` each (left, top, right,
    bottom, pixels): an edge is cut where ``edge <= low`` or ``edge >= high`` (NaN: never)."""
    width, height = image_size
    nan = float("nan")
    return (
        np.array([tol_px, tol_px, nan, nan]),
        np.array([nan, nan, width - 1 - tol_px, height - 1 - tol_px]),
    )


def cuts_at(
    boxes: NDArray[np.float64], limits: tuple[NDArray[np.float64], NDArray[np.float64]]
) -> NDArray[np.bool_]:
    """:func:`border_cuts` of boxes ``(N, 4)`` at the limits of :func:`border_cut_limits`."""
    low, high = limits
    return (boxes <= low) | (boxes >= high)


def cut_labels(cuts: NDArray[np.bool_]) -> NDArray[np.object_]:
    """The ``cut`` column of :func:`border_cuts` flags: ``""`` or the cut edges in
    :data:`EDGES` order joined by ``+`` (``"bottom"``, ``"left+bottom"``)."""
    c = np.asarray(cuts, dtype=bool).reshape(-1, 4)
    return _CUT_LABELS[c.dot(_EDGE_BITS)]


def class_key(name: object) -> str:
    """A class name as class names are compared (:func:`vehicle_mask`, the generic classes
    of ``ours``): case and surrounding spaces ignored."""
    return str(name).strip().lower()


def vehicle_mask(
    classes: ArrayLike, vehicle_classes: Iterable[str] = DEFAULT_VEHICLE_CLASSES
) -> NDArray[np.bool_]:
    """Per box, whether its class name is one of ``vehicle_classes`` (case-insensitive,
    surrounding spaces ignored)."""
    wanted = {class_key(c) for c in vehicle_classes}
    names = np.asarray(classes, dtype=object).reshape(-1)
    return np.array([class_key(c) in wanted for c in names], dtype=bool)


def iou_matrix(boxes_a: ArrayLike, boxes_b: ArrayLike) -> NDArray[np.float64]:
    """2D intersection over union of every pair, shape ``(len(a), len(b))``."""
    a = np.asarray(boxes_a, dtype=float).reshape(-1, 4)[:, None, :]
    b = np.asarray(boxes_b, dtype=float).reshape(-1, 4)[None, :, :]
    return _iou(a, b)


def pair_iou(
    boxes_a: ArrayLike, boxes_b: ArrayLike, i: NDArray[np.intp], j: NDArray[np.intp]
) -> NDArray[np.float64]:
    """IoU of the pairs ``(a[i[k]], b[j[k]])`` only (the entries of :func:`iou_matrix`, bit for
    bit), shape ``(len(i),)``."""
    a = np.asarray(boxes_a, dtype=float).reshape(-1, 4)
    b = np.asarray(boxes_b, dtype=float).reshape(-1, 4)
    return _iou(a[i], b[j])


def _iou(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Elementwise IoU of broadcast boxes ``(..., 4)``."""
    iw = np.clip(np.minimum(a[..., 2], b[..., 2]) - np.maximum(a[..., 0], b[..., 0]), 0, None)
    ih = np.clip(np.minimum(a[..., 3], b[..., 3]) - np.maximum(a[..., 1], b[..., 1]), 0, None)
    inter = iw * ih
    area_a = (a[..., 2] - a[..., 0]) * (a[..., 3] - a[..., 1])
    area_b = (b[..., 2] - b[..., 0]) * (b[..., 3] - b[..., 1])
    union = area_a + area_b - inter
    with np.errstate(divide="ignore", invalid="ignore"):
        iou = np.where(union > 0, inter / union, 0.0)
    return np.asarray(iou)


def overlapping_pairs(
    boxes_a: ArrayLike, boxes_b: ArrayLike
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Index pairs ``(i, j)`` of boxes ``a[i]`` and ``b[j]`` whose interiors overlap
    (``min(right) > max(left)`` and ``min(bottom) > max(top)``), in no particular order.

    Boxes that are not finite with right > left and bottom > top overlap nothing. A sort and
    sweep over the columns: ``O((n + m) log(n + m))`` plus the number of pairs that overlap in
    columns, instead of the ``n·m`` of testing every pair.
    """
    a = np.asarray(boxes_a, dtype=float).reshape(-1, 4)
    b = np.asarray(boxes_b, dtype=float).reshape(-1, 4)
    ia, ib = proper_box_rows(a), proper_box_rows(b)
    a, b = a[ia], b[ib]
    # a pair overlaps in columns iff the later-starting box starts before the other ends:
    # b starts within [left_a, right_a), or a starts within (left_b, right_b)
    i1, j1 = _starts_within(a[:, 0], a[:, 2], b[:, 0], "left")
    j2, i2 = _starts_within(b[:, 0], b[:, 2], a[:, 0], "right")
    i, j = np.concatenate([i1, i2]), np.concatenate([j1, j2])
    rows = np.minimum(a[i, 3], b[j, 3]) > np.maximum(a[i, 1], b[j, 1])
    return ia[i[rows]], ib[j[rows]]


def proper_box_rows(boxes: NDArray[np.float64]) -> NDArray[np.intp]:
    """Indices of the finite boxes with right > left and bottom > top."""
    ok = np.isfinite(boxes).all(axis=1) & (boxes[:, 2] > boxes[:, 0]) & (boxes[:, 3] > boxes[:, 1])
    return np.flatnonzero(ok)


def _starts_within(
    lo: NDArray[np.float64],
    hi: NDArray[np.float64],
    starts: NDArray[np.float64],
    side: Literal["left", "right"],
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Pairs ``(k, m)`` with ``starts[m]`` in ``[lo[k], hi[k])`` (``side="left"``) or in
    ``(lo[k], hi[k])`` (``side="right"``)."""
    order = np.argsort(starts, kind="stable")
    sorted_starts = starts[order]
    first = np.searchsorted(sorted_starts, lo, side=side)
    last = np.searchsorted(sorted_starts, hi, side="left")
    counts = np.maximum(last - first, 0)
    k = np.repeat(np.arange(lo.shape[0]), counts)
    offset = np.arange(k.shape[0]) - np.repeat(np.cumsum(counts) - counts, counts)
    return k, order[np.repeat(first, counts) + offset]


def _row_selection(mask: ArrayLike, n: int) -> NDArray:
    """``mask`` as a boolean mask of ``n`` rows or an array of row indices in ``-n..n-1``
    (:meth:`BoxTable.select`).

    Raises:
        DataMismatchError: anything else (numpy's IndexError, or a scalar that would turn the
            columns into single values).
    """
    m = np.asarray(mask)
    if m.ndim == 1 and m.size == 0:
        return m.astype(np.intp)
    if m.ndim != 1 or not (m.dtype == np.bool_ or np.issubdtype(m.dtype, np.integer)):
        raise DataMismatchError(
            f"box selection must be a boolean mask or an array of row indices, got "
            f"{m.dtype} of shape {m.shape}"
        )
    if m.dtype == np.bool_:
        if m.shape[0] != n:
            raise DataMismatchError(
                f"box selection mask has {m.shape[0]} values for a table of {n} boxes"
            )
    elif m.min() < -n or m.max() >= n:
        bad = int(m[(m < -n) | (m >= n)][0])
        raise DataMismatchError(f"box selection index {bad} is outside a table of {n} boxes")
    return m


def _column(
    name: str, values: ArrayLike, dtype: type[np.generic], shape: tuple[int, ...] | None
) -> NDArray:
    """``values`` as a ``dtype`` array of ``shape`` (None: flattened) for :meth:`BoxTable.build`.

    Raises:
        DataMismatchError: the values do not convert or do not fit the shape.
    """
    try:
        # a NaN, an infinity or a number beyond int64 casts to garbage (numpy warns: "invalid
        # value encountered in cast"), which the whole-number check below refuses
        with np.errstate(invalid="ignore", over="ignore"):
            arr = np.asarray(values, dtype=dtype)
        if np.issubdtype(dtype, np.integer):  # whole numbers only: 0.5 is no frame index
            exact = np.asarray(values, dtype=np.float64).reshape(-1)
            wrong = np.flatnonzero(exact != arr.reshape(-1).astype(np.float64))
            if wrong.size:
                k = int(wrong[0])
                raise ValueError(f"{exact[k]:g} (entry {k}) is not a whole number")
    except (TypeError, ValueError, OverflowError) as exc:
        raise DataMismatchError(f"box table column '{name}': {exc}") from None
    if shape is None:
        return arr.reshape(-1)
    if arr.size != int(np.prod(shape)):
        raise DataMismatchError(
            f"box table column '{name}' has {arr.size} values for {shape[0]} boxes"
            + (f" ({shape[1]} per box)" if len(shape) > 1 else "")
        )
    return arr.reshape(shape)


@dataclass(frozen=True)
class BoxTable:
    """2D boxes of one or many frames, as parallel numpy columns of length N.

    Attributes:
        frame: ``(N,)`` int frame index.
        boxes: ``(N, 4)`` float (left, top, right, bottom), pixels.
        track_id: ``(N,)`` int, :data:`NO_TRACK` where unknown.
        score: ``(N,)`` float detector score, NaN where unknown.
        cls: ``(N,)`` object array of class names (``"Car"``, ``"Van"``, ...).
        extra: further per-box columns, e.g. ``"z"`` (ground-truth longitudinal distance, m),
            ``"truncated"``, ``"occluded"``, ``"dims_hwl"`` (``(N, 3)``, m).
    """

    frame: NDArray[np.int64]
    boxes: NDArray[np.float64]
    track_id: NDArray[np.int64]
    score: NDArray[np.float64]
    cls: NDArray[np.object_]
    extra: dict[str, NDArray] = field(default_factory=dict)

    @classmethod
    def build(
        cls,
        frame: ArrayLike,
        boxes: ArrayLike,
        track_id: ArrayLike | None = None,
        score: ArrayLike | None = None,
        classes: ArrayLike | None = None,
        **extra: ArrayLike,
    ) -> BoxTable:
        """Build a table, filling unknown columns (no track, NaN score, class ``"Car"``).

        Raises:
            DataMismatchError: a column that is not one value per frame entry (``boxes``: four)
                or not numbers (a NaN frame index, a text coordinate).
        """
        fr = _column("frame", frame, np.int64, None)
        n = fr.shape[0]
        bx = _column("boxes", boxes, np.float64, (n, 4))
        tid = (
            np.full(n, NO_TRACK, np.int64)
            if track_id is None
            else _column("track_id", track_id, np.int64, (n,))
        )
        sc = np.full(n, np.nan) if score is None else _column("score", score, np.float64, (n,))
        cl = (
            np.full(n, "Car", dtype=object)
            if classes is None
            else _column("classes", classes, np.object_, (n,))
        )
        columns = {k: np.asarray(v) for k, v in extra.items()}
        for k, v in columns.items():
            if v.ndim == 0 or v.shape[0] != n:
                raise DataMismatchError(
                    f"box table column '{k}' has {v.shape[0] if v.ndim else 'a single'} "
                    f"value(s) for {n} boxes"
                )
        return cls(fr, bx, tid, sc, cl, columns)

    @classmethod
    def empty(cls) -> BoxTable:
        """A table with no boxes."""
        return cls.build(np.zeros(0, np.int64), np.zeros((0, 4)))

    def __len__(self) -> int:
        return int(self.frame.shape[0])

    def select(self, mask: ArrayLike) -> BoxTable:
        """Rows where ``mask`` is true (or at the given indices).

        Raises:
            DataMismatchError: a boolean mask that is not one value per box, or indices that
                are not whole numbers within the table (negative ones count from the end).
        """
        m = _row_selection(mask, len(self))
        return BoxTable(
            self.frame[m],
            self.boxes[m],
            self.track_id[m],
            self.score[m],
            self.cls[m],
            {k: v[m] for k, v in self.extra.items()},
        )

    def frames(self) -> NDArray[np.int64]:
        """Sorted unique frame indices present."""
        return np.unique(self.frame)

    def by_frame(self) -> Iterator[tuple[int, BoxTable]]:
        """Yield ``(frame index, boxes of that frame)`` in frame order (nothing for an empty
        table)."""
        if len(self) == 0:
            return
        order = np.argsort(self.frame, kind="stable")
        sorted_frames = self.frame[order]
        starts = np.flatnonzero(np.r_[True, np.diff(sorted_frames) != 0])
        ends = np.r_[starts[1:], len(order)]
        for s, e in zip(starts, ends):
            yield int(sorted_frames[s]), self.select(order[s:e])

    def frame_index(self) -> dict[int, BoxTable]:
        """``{frame index: boxes of that frame}``."""
        return dict(self.by_frame())

    def frame_lookup(self) -> FrameLookup:
        """The boxes of each frame, cut out when asked for (:class:`FrameLookup`)."""
        return FrameLookup(self)


class FrameLookup(Mapping[int, "BoxTable"]):
    """``{frame index: boxes of that frame}`` like :meth:`BoxTable.frame_index`, but each
    frame's table is cut out of ``table`` when it is asked for, so a long drive's boxes are
    held once (plus 8 bytes per box and 24 per frame), not as one small table per frame.
    The rows of a frame come in the order of ``table`` (as :meth:`BoxTable.by_frame`)."""

    def __init__(self, table: BoxTable) -> None:
        self.table = table
        self._order = np.argsort(table.frame, kind="stable")
        frames = table.frame[self._order]
        starts = np.flatnonzero(np.r_[True, np.diff(frames) != 0]) if len(frames) else frames
        self._keys = frames[starts]
        self._bounds = np.r_[starts, len(frames)].astype(np.int64)

    def _position(self, frame: object) -> int:
        """Position of ``frame`` among the frames with boxes, or -1."""
        if not isinstance(frame, (int, np.integer)):
            return -1
        i = int(np.searchsorted(self._keys, frame))
        return i if i < len(self._keys) and self._keys[i] == frame else -1

    def __getitem__(self, frame: int) -> BoxTable:
        i = self._position(frame)
        if i < 0:
            raise KeyError(frame)
        return self.table.select(self._order[self._bounds[i] : self._bounds[i + 1]])

    def __contains__(self, frame: object) -> bool:
        return self._position(frame) >= 0

    def __iter__(self) -> Iterator[int]:
        return (int(k) for k in self._keys)

    def __len__(self) -> int:
        return len(self._keys)

    def count(self, frame: int) -> int:
        """Number of boxes of ``frame`` (0 when it has none)."""
        i = self._position(frame)
        return int(self._bounds[i + 1] - self._bounds[i]) if i >= 0 else 0


def concat_boxes(parts: list[BoxTable], like: BoxTable | None = None) -> BoxTable:
    """Concatenate box tables (columns present in every part are kept).

    With no part, the result is empty with the columns of ``like`` (e.g. the table the parts
    were cut from), so that a sequence without any box keeps its extra columns.
    """
    if not parts:
        return BoxTable.empty() if like is None else like.select(np.zeros(len(like), bool))
    keys = set.intersection(*(set(p.extra) for p in parts))
    return BoxTable(
        np.concatenate([p.frame for p in parts]),
        np.concatenate([p.boxes for p in parts]),
        np.concatenate([p.track_id for p in parts]),
        np.concatenate([p.score for p in parts]),
        np.concatenate([p.cls for p in parts]),
        {k: np.concatenate([p.extra[k] for p in parts]) for k in keys},
    )


FRAME_BOX_COLUMN = "frame_box"
"""Extra column of a :class:`BoxTable` whose boxes were mapped into an ideal camera (lens
distortion, ``fx ≠ fy`` taken out: :meth:`slopedist.io.intrinsics.Intrinsics.rectify_table`):
the boxes as they were, ``(N, 4)`` pixels of the frame."""


def frame_pixel_boxes(table: BoxTable) -> NDArray[np.float64]:
    """``(N, 4)`` boxes of ``table`` in the frame's own pixels: :data:`FRAME_BOX_COLUMN` when
    they were mapped into an ideal camera, else the boxes themselves. What the image border
    cuts is judged here: a mapped box's edges move by the lens model, in or out of the image."""
    original = table.extra.get(FRAME_BOX_COLUMN)
    return table.boxes if original is None else np.asarray(original, dtype=float)


def table_box_problems(
    table: BoxTable, image_size: tuple[int, int] | None = None
) -> NDArray[np.object_]:
    """:func:`box_problems` of ``table``'s boxes, with ``outside_image`` judged in the frame's
    own pixels (:func:`frame_pixel_boxes`): a box the frame shows is in the image even when a
    lens model maps it beyond the ideal camera's edges (barrel distortion moves them out)."""
    reasons = box_problems(table.boxes, image_size)
    if image_size is None or FRAME_BOX_COLUMN not in table.extra:
        return reasons
    outside = box_problems(frame_pixel_boxes(table), image_size) == "outside_image"
    reasons[reasons == "outside_image"] = ""
    reasons[(reasons == "") & outside] = "outside_image"
    return reasons
