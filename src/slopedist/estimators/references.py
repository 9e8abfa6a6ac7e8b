"""Distances moved from the point of the vehicle a method reports to another one.

Methods report different points of a vehicle (``FrameEstimates.reference``): the ground-contact
methods (``flat``, ``ego``, ``paper``, ``imu``, ``imu-ego``) the contact row under the box
bottom, which for a vehicle ahead is the ground under its nearest face; ``ours`` its centre
(KITTI's label z), its nearest face or its contact point, as asked; ``depthmap`` the surface
seen at the box's centre pixel. Ground truth refers to one of them too (KITTI labels: the
centre; LiDAR clusters: the nearest face). An evaluation compares like with like by moving
every method's distance to the truth's point with :func:`to_reference`.

Along the camera's z axis the contact point and the nearest face are the same distance (the
contact row is the foot of the nearest face), and so is a visible surface point; the centre
lies half the vehicle's depth extent farther. That half extent is the method's own where it
reports one (``ours``: ``distance_centre_m − distance_nearest_face_m``), otherwise half the
length prior of the box's class (:func:`~slopedist.estimators.prior_for`: a
vehicle seen from behind). Distances in metres.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slopedist.estimators import prior_for
from slopedist.estimators.base import ReferencePoint

CENTRE_COLUMN = "distance_centre_m"
"""Extra column of a method that reports the distance to the centre whatever its main one."""
NEAREST_FACE_COLUMN = "distance_nearest_face_m"
"""Extra column of a method that reports the distance to the nearest face whatever its main
one."""

_FACE_POINTS = frozenset(
    {
        ReferencePoint.CONTACT.value,
        ReferencePoint.NEAREST_FACE.value,
        ReferencePoint.BOX_CENTRE_PIXEL.value,
    }
)
"""Reference points at the nearest face's longitudinal distance."""

FloatArray = NDArray[np.float64]


def half_length_prior_m(classes: ArrayLike) -> FloatArray:
    """Half the length prior of each class name (metres; unknown names: the broad prior)."""
    cls = np.asarray(classes, dtype=object).ravel()
    halves = {c: 0.5 * prior_for(str(c)).length_m for c in set(cls.tolist())}
    return np.array([halves[c] for c in cls.tolist()], dtype=float)


def own_half_extent_m(extra: Mapping[str, ArrayLike], n: int) -> FloatArray:
    """The half depth extent a method reports itself (centre minus nearest-face columns), NaN
    per row where it reports none."""
    if CENTRE_COLUMN not in extra or NEAREST_FACE_COLUMN not in extra:
        return np.full(n, np.nan)
    centre = np.asarray(extra[CENTRE_COLUMN], dtype=float)
    face = np.asarray(extra[NEAREST_FACE_COLUMN], dtype=float)
    return centre - face


def to_reference(
    distance_m: ArrayLike,
    reported: ArrayLike,
    classes: ArrayLike,
    wanted: ReferencePoint,
    half_extent_m: ArrayLike | None = None,
) -> FloatArray:
    """Distances (metres) moved from each row's ``reported`` reference point to ``wanted``.

    Args:
        distance_m: the method's distances, metres (NaN stays NaN).
        reported: per row, the :class:`ReferencePoint` value the distance refers to.
        classes: per row, the box's class name (for the length prior).
        wanted: the point to report, e.g. the ground truth's.
        half_extent_m: per row, the method's own half depth extent (metres; NaN or None: half
            the class's length prior).

    Returns:
        A new array: unchanged where both points are at the same distance, plus (face to
        centre) or minus (centre to face) the half extent elsewhere.
    """
    d = np.array(distance_m, dtype=float).ravel()
    rep = np.asarray(reported, dtype=object).ravel()
    half = half_length_prior_m(classes)
    if half_extent_m is not None:
        own = np.asarray(half_extent_m, dtype=float).ravel()
        half = np.where(np.isfinite(own), own, half)
    is_face = np.array([r in _FACE_POINTS for r in rep.tolist()], dtype=bool)
    is_centre = rep == ReferencePoint.CENTRE.value
    if ReferencePoint(wanted) is ReferencePoint.CENTRE:
        d[is_face] += half[is_face]
    else:
        d[is_centre] -= half[is_centre]
    return d
