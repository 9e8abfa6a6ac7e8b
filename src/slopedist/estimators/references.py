"""Distances moved from the point of the vehicle a method reports to another one.

Methods report different points of a vehicle (``FrameEstimates.reference``): the ground-contact
methods (``flat``, ``ego``, ``paper``, ``imu``, ``imu-ego``) the contact row under the box
bottom, which for a vehicle ahead is the ground under its nearest face; ``ours`` its centre
(KITTI's label z), its nearest face or its contact point, as asked; ``depthmap`` the surface
seen at the box's centre pixel. Ground truth refers to one of them too (KITTI labels: the
centre; LiDAR clusters: the nearest face). An evaluation compares like with like by moving
every method's distance to the truth's point with :func:`to_reference`. What a user sees
(``run``, ``estimate``, ``batch``, the overlay, ``tracks.csv``) is every method's estimate
moved to :data:`DEFAULT_REFERENCE`, the gap to the vehicle's nearest face, unless another
point is asked for (:func:`at_reference`).

Along the camera's z axis the contact point and the nearest face are the same distance (the
contact row is the foot of the nearest face), and so is a visible surface point; the centre
lies half the vehicle's depth extent farther. That half extent is the method's own where it
reports one (``ours``: ``distance_centre_m − distance_nearest_face_m``), otherwise half the
length prior of the box's class (:func:`~slopedist.estimators.prior_for`: a
vehicle seen from behind). Distances in metres.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slopedist.estimators import prior_for
from slopedist.estimators.base import FrameEstimates, ReferencePoint

DEFAULT_REFERENCE = ReferencePoint.NEAREST_FACE
"""The point of a vehicle the distances a user sees refer to unless another is asked for
(``--reference``): its nearest face (the rear of a car ahead), so that ``distance_m`` is the
gap a following distance, a headway or a time to collision is about. ``run``, ``estimate``,
``batch``, their overlays and ``tracks.csv`` and the Python API report it; an evaluation
against a truth compares at the truth's point instead (KITTI's label z: the centre)."""

TTC_COLUMNS = ("ttc_s", "ttc_sigma_s")
"""Extra columns of a time to collision and its 1σ (seconds): the time until the distance
closes, so a distance moved to another point moves them in proportion."""

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


def reported_labels(reported: ArrayLike, wanted: ReferencePoint) -> NDArray[np.object_]:
    """The ``reference`` of each row once its distance is moved to ``wanted``: ``wanted``,
    except that a row at the ``contact`` point stays ``contact`` when the nearest face is asked
    for (the ground under the nearest face, the same distance: what the ground-contact methods
    measure)."""
    rep = np.asarray(reported, dtype=object).ravel()
    out = np.full(rep.shape, ReferencePoint(wanted).value, dtype=object)
    if ReferencePoint(wanted) is ReferencePoint.NEAREST_FACE:
        out[rep == ReferencePoint.CONTACT.value] = ReferencePoint.CONTACT.value
    return out


def at_reference(est: FrameEstimates, classes: ArrayLike, wanted: ReferencePoint) -> FrameEstimates:
    """A frame's estimates with every distance moved to ``wanted`` (:func:`to_reference`, by
    the method's own half extent where it reports one, else half the length prior of the
    box's class ``classes``), the ``reference`` column saying where each now is
    (:func:`reported_labels`) and a time to collision (:data:`TTC_COLUMNS`) scaled with the
    distance it closes. The 1σ ``sigma_m`` stays the method's own; the method's arrays are
    not changed (a new :class:`FrameEstimates`)."""
    n = len(est)
    if not n:
        return est
    wanted = ReferencePoint(wanted)
    moved = to_reference(
        est.distance_m, est.reference, classes, wanted, own_half_extent_m(est.extra, n)
    )
    extra = dict(est.extra)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.where(est.distance_m > 0, moved / est.distance_m, np.nan)
    for name in TTC_COLUMNS:
        if name in extra:
            extra[name] = np.asarray(extra[name], dtype=float) * ratio
    return dataclasses.replace(
        est,
        distance_m=moved,
        reference=reported_labels(est.reference, wanted),
        extra=extra,
        status=est.status.copy(),
        cut=est.cut.copy(),
    )
