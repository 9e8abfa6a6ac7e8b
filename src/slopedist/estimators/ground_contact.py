"""The ground-contact estimators: flat ground, ego gradient only, and the paper's method.

All three read eq. 1 ``d = f·h/(u − v)``; they differ in the vanishing-line row ``v``:
``flat`` puts it at ``c_y`` (a level road, θ = θ0 = 0); ``ego`` moves it with the ego road
gradient θ (eq. 5); ``paper`` additionally raises θ per target by the steps of eq. 7.

Border: a box cut by the bottom of the image hides its contact row, which is lower than the
box bottom, so eq. 1 gives a distance the true one does not exceed: status ``upper_bound``,
reason ``cut_bottom``, distance kept (for ``paper``/``imu`` this holds while the cut does not
change the eq. 7 step, i.e. while the visible box centre stays below the horizon, as it does
for any car near enough to be cut). A box cut only at a side or the top still shows its
contact row: ``ok``, with the ``cut`` flag.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from slopedist.core import geometry as geo
from slopedist.core.camera import Camera
from slopedist.core.errors import ConfigurationError
from slopedist.estimators.base import (
    MIN_RESOLVED_PX,
    Estimator,
    FrameEstimates,
    FrameInput,
    MissingReason,
    ReferencePoint,
    bottom_cut_is_upper_bound,
    unusable_box_reasons,
)
from slopedist.io.detections.boxes import frame_pixel_boxes


def ground_contact_estimates(
    camera: Camera,
    theta_rad: NDArray[np.float64],
    theta_adj_rad: NDArray[np.float64],
    boxes: NDArray[np.float64],
    prior_reasons: NDArray[np.object_],
    frame_boxes: NDArray[np.float64],
) -> FrameEstimates:
    """Eq. 5 then eq. 1 for every box, with the per-box gradient ``theta_adj_rad`` (radians);
    a box bottom less than :data:`~slopedist.estimators.base.MIN_RESOLVED_PX` below the
    vanishing line is ``missing``, reason ``near_horizon`` (at or above it, ``below_horizon``).

    ``Δy`` (eq. 6) is reported against the vanishing line of the unadjusted θ. A box cut by
    the bottom of the image (``camera``'s size) is an ``upper_bound``
    (:func:`~slopedist.estimators.base.bottom_cut_is_upper_bound`), judged on ``frame_boxes``,
    the boxes in the frame's own pixels (``boxes`` themselves unless a lens model mapped them:
    :func:`~slopedist.io.detections.boxes.frame_pixel_boxes`).
    """
    v_ego = geo.vanishing_line_row(theta_rad, camera.f, camera.c_y)
    delta_y = geo.target_offset_px(geo.box_centre_row(boxes), v_ego)
    v = geo.vanishing_line_row(theta_adj_rad, camera.f, camera.c_y)
    u = geo.box_bottom_row(boxes)
    d = geo.ground_contact_distance(camera.f, camera.height_m, u, v)
    reasons = prior_reasons.copy()
    reasons[(reasons == "") & ~np.isfinite(d)] = MissingReason.BELOW_HORIZON.value
    reasons[(reasons == "") & (u - v < MIN_RESOLVED_PX)] = MissingReason.NEAR_HORIZON.value
    d = np.where(reasons == "", d, np.nan)
    n = boxes.shape[0]
    est = FrameEstimates(
        theta_rad=np.broadcast_to(theta_rad, (n,)).astype(float),
        theta_adj_rad=np.broadcast_to(theta_adj_rad, (n,)).astype(float),
        delta_y_px=np.broadcast_to(delta_y, (n,)).astype(float),
        v_px=np.broadcast_to(v, (n,)).astype(float),
        distance_m=d,
        reason=reasons,
        reference=np.full(n, ReferencePoint.CONTACT.value, dtype=object),
    )
    bottom_cut_is_upper_bound(est, frame_boxes, camera)
    return est


class FlatGroundEstimator(Estimator):
    """Classic pinhole model on a level road: eq. 1 with the vanishing line of a camera at rest.

    θ is eq. 4 with no rotation (``ΔR_prev = ΔR_curr = I``), which is ``−θ0``; with θ0 = 0 the
    vanishing line is the principal-point row ``c_y``.
    """

    name: ClassVar[str] = "flat"
    handles_border_cuts: ClassVar[bool] = True
    needs_rotation: ClassVar[bool] = False

    def estimate(self, frame: FrameInput) -> FrameEstimates:
        boxes = frame.boxes.boxes
        theta_rest = geo.rest_gradient(self.camera.mount_angle_rad)
        theta = np.full(len(boxes), theta_rest)
        return ground_contact_estimates(
            self.camera,
            theta,
            theta,
            boxes,
            unusable_box_reasons(frame, False, self.camera),
            frame_pixel_boxes(frame.boxes),
        )


class EgoGradientEstimator(Estimator):
    """The paper's ablation "before updating": eq. 1 with v from the ego gradient θ (eq. 4–5)."""

    name: ClassVar[str] = "ego"
    handles_border_cuts: ClassVar[bool] = True

    def estimate(self, frame: FrameInput) -> FrameEstimates:
        boxes = frame.boxes.boxes
        theta = np.full(len(boxes), frame.theta_rad)
        return ground_contact_estimates(
            self.camera,
            theta,
            theta,
            boxes,
            unusable_box_reasons(frame, True, self.camera),
            frame_pixel_boxes(frame.boxes),
        )


class PaperEstimator(Estimator):
    """The paper's method: ego gradient plus the per-target adjustment of eq. 6–7."""

    name: ClassVar[str] = "paper"
    handles_border_cuts: ClassVar[bool] = True

    def __init__(self, camera: Camera, adjustment: geo.GradientAdjustment | None = None) -> None:
        super().__init__(camera)
        if adjustment is not None and not isinstance(adjustment, geo.GradientAdjustment):
            raise ConfigurationError(
                f"option adjustment of method '{self.name}' must be a GradientAdjustment "
                f"(e.g. GradientAdjustment.from_degrees), got {adjustment!r}"
            )
        self.adjustment = adjustment or geo.GradientAdjustment()

    def estimate(self, frame: FrameInput) -> FrameEstimates:
        boxes = frame.boxes.boxes
        theta = np.full(len(boxes), frame.theta_rad)
        v = geo.vanishing_line_row(theta, self.camera.f, self.camera.c_y)
        delta_y = geo.target_offset_px(geo.box_centre_row(boxes), v)
        theta_adj = geo.adjusted_gradient(theta, delta_y, self.adjustment)
        return ground_contact_estimates(
            self.camera,
            theta,
            theta_adj,
            boxes,
            unusable_box_reasons(frame, True, self.camera),
            frame_pixel_boxes(frame.boxes),
        )
