"""The box table: 2D boxes of many frames as numpy columns, and box checks and overlap.

Convention: boxes are ``(left, top, right, bottom)`` in pixels, origin top-left, rows downwards.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

NO_TRACK = -1
"""Track id used when a box has no track id."""


def box_problems(boxes: ArrayLike) -> NDArray[np.object_]:
    """Reason a box cannot be used, per box: ``""`` if fine, else ``non_finite_box`` or
    ``inverted_box`` (right ≤ left or bottom ≤ top)."""
    b = np.asarray(boxes, dtype=float).reshape(-1, 4)
    reasons = np.full(b.shape[0], "", dtype=object)
    finite = np.all(np.isfinite(b), axis=1)
    inverted = finite & ((b[:, 2] <= b[:, 0]) | (b[:, 3] <= b[:, 1]))
    reasons[~finite] = "non_finite_box"
    reasons[inverted] = "inverted_box"
    return reasons


def iou_matrix(boxes_a: ArrayLike, boxes_b: ArrayLike) -> NDArray[np.float64]:
    """2D intersection over union of every pair, shape ``(len(a), len(b))``."""
    a = np.asarray(boxes_a, dtype=float).reshape(-1, 4)[:, None, :]
    b = np.asarray(boxes_b, dtype=float).reshape(-1, 4)[None, :, :]
    iw = np.clip(np.minimum(a[..., 2], b[..., 2]) - np.maximum(a[..., 0], b[..., 0]), 0, None)
    ih = np.clip(np.minimum(a[..., 3], b[..., 3]) - np.maximum(a[..., 1], b[..., 1]), 0, None)
    inter = iw * ih
    area_a = (a[..., 2] - a[..., 0]) * (a[..., 3] - a[..., 1])
    area_b = (b[..., 2] - b[..., 0]) * (b[..., 3] - b[..., 1])
    union = area_a + area_b - inter
    with np.errstate(divide="ignore", invalid="ignore"):
        iou = np.where(union > 0, inter / union, 0.0)
    return np.asarray(iou)


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
        """Build a table, filling unknown columns (no track, NaN score, class ``"Car"``)."""
        fr = np.asarray(frame, dtype=np.int64).reshape(-1)
        n = fr.shape[0]
        bx = np.asarray(boxes, dtype=float).reshape(n, 4)
        tid = (
            np.full(n, NO_TRACK, np.int64)
            if track_id is None
            else np.asarray(track_id, dtype=np.int64).reshape(n)
        )
        sc = np.full(n, np.nan) if score is None else np.asarray(score, dtype=float).reshape(n)
        cl = (
            np.full(n, "Car", dtype=object)
            if classes is None
            else np.asarray(classes, dtype=object).reshape(n)
        )
        return cls(fr, bx, tid, sc, cl, {k: np.asarray(v) for k, v in extra.items()})

    @classmethod
    def empty(cls) -> BoxTable:
        """A table with no boxes."""
        return cls.build(np.zeros(0, np.int64), np.zeros((0, 4)))

    def __len__(self) -> int:
        return int(self.frame.shape[0])

    def select(self, mask: ArrayLike) -> BoxTable:
        """Rows where ``mask`` is true (or at the given indices)."""
        m = np.asarray(mask)
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
        """Yield ``(frame index, boxes of that frame)`` in frame order."""
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


def concat_boxes(parts: list[BoxTable]) -> BoxTable:
    """Concatenate box tables (columns present in every part are kept)."""
    if not parts:
        return BoxTable.empty()
    keys = set.intersection(*(set(p.extra) for p in parts))
    return BoxTable(
        np.concatenate([p.frame for p in parts]),
        np.concatenate([p.boxes for p in parts]),
        np.concatenate([p.track_id for p in parts]),
        np.concatenate([p.score for p in parts]),
        np.concatenate([p.cls for p in parts]),
        {k: np.concatenate([p.extra[k] for p in parts]) for k in keys},
    )
