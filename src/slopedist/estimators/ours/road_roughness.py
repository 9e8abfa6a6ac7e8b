"""What the ego's own gradient history tells of the drive: how rough its road is
(experimental setting ``adapt_contact_trust``) and how noisy its θ is (``learn_horizon_jitter``).

The ground contact's trust is set by the target-gradient prior (``gradient_sigma_rad``) and the
horizon jitter (``theta_sigma_rad``), both KITTI's statistics. The targets drive the road the
ego drives, so the ego's own measured gradient θ tells how far this drive's road departs from
a plane: θ of eq. 4 is the camera's pitch change over the one-second look-back (plus the
mount's rest gradient), and ``θ − θ_rest`` is the road's gradient change over the last second
(with the body's pitch and the odometry's noise, which only make it larger). Its mean square
over the drive so far, against KITTI's (:data:`KITTI_THETA_RMS_RAD`), is the scale ``r`` the
two KITTI variances are multiplied by: a road flatter than KITTI's gets a ground contact
trusted more, a rougher one less.

``r`` is the posterior mean of a variance ratio under a prior of one look-back's worth of
KITTI (``r = 1``): ``r = (1 + Σ wᵢ (θᵢ − θ_rest)²/s²)/(1 + Σ wᵢ)``, each frame weighing
``wᵢ = dtᵢ/1 s`` (the frames of one look-back share their θ's interval), bounded to
[:data:`MIN_SCALE`, :data:`MAX_SCALE`]. It is causal: each frame's cues use the θ of the frames
before it and its own.

Radians, seconds.
"""

from __future__ import annotations

import math

KITTI_THETA_RMS_RAD = math.radians(0.39)
"""RMS of ``θ − θ_rest`` over the 13 shared KITTI tracking sequences (ORB-SLAM3 rotations, 1 s
look-back; 0.32–0.40° leaving one sequence out): the roughness the KITTI priors go with."""

LOOK_BACK_S = 1.0
"""The look-back of θ (eq. 4): frames within it share their interval (one independent sample
of the gradient change per look-back)."""

PRIOR_WEIGHT = 1.0
"""Weight of the KITTI prior (r = 1), in look-backs."""

MIN_SCALE = 1e-3
"""Smallest scale: the target gradient's spread stays above 1°·√0.001 = 0.03°."""

MAX_SCALE = 4.0
"""Largest scale: the spreads at most twice KITTI's (a rough road or a noisy odometry)."""


class RoadRoughness:
    """Causal estimate of the drive's road roughness against KITTI's (see the module)."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Forget the drive (a new sequence)."""
        self._sum = 0.0
        self._weight = 0.0
        self._last_time_s = math.nan

    def update(self, time_s: float, theta_change_rad: float) -> None:
        """Add a frame with a measured θ: ``theta_change_rad`` = θ − θ_rest (rad) at
        ``time_s`` (s). A frame's weight is its time since the last one (at most a look-back; the
        first frame's θ, over no interval, weighs nothing)."""
        last = self._last_time_s
        dt = 0.0 if math.isnan(last) else min(max(time_s - last, 0.0), LOOK_BACK_S)
        self._last_time_s = time_s
        w = dt / LOOK_BACK_S
        self._sum += w * (theta_change_rad / KITTI_THETA_RMS_RAD) ** 2
        self._weight += w

    @property
    def scale(self) -> float:
        """The variance scale ``r`` (1: KITTI's roughness)."""
        r = (PRIOR_WEIGHT + self._sum) / (PRIOR_WEIGHT + self._weight)
        return min(max(r, MIN_SCALE), MAX_SCALE)


JITTER_PRIOR_COUNT = 3.0
"""Weight of the configured horizon jitter in its online estimate, in second differences."""


class HorizonJitter:
    """The ego gradient θ's per-frame noise, estimated online (experimental setting
    ``learn_horizon_jitter``).

    The second difference ``θ_k − 2θ_{k−1} + θ_{k−2}`` of three evenly spaced frames has
    variance ``6σ²`` for a white noise σ (a real pitch motion only adds to it, so the estimate
    errs wide); pooled with :data:`JITTER_PRIOR_COUNT` pseudo-observations of the configured
    jitter. Only frames at most ``max_gap_s`` apart and evenly spaced (within 1 ms) count.

    Args:
        prior_rad: the configured jitter (rad).
        max_gap_s: the largest frame spacing a second difference spans, seconds.
    """

    def __init__(self, prior_rad: float, max_gap_s: float = 0.2) -> None:
        self._prior2 = prior_rad**2
        self._max_gap_s = max_gap_s
        self.reset()

    def reset(self) -> None:
        """Forget the drive."""
        self._last: list[tuple[float, float]] = []
        self._sum = 0.0
        self._count = 0

    def update(self, time_s: float, theta_rad: float) -> None:
        """A frame's measured θ (rad) at ``time_s`` (s)."""
        self._last = [*self._last[-2:], (time_s, theta_rad)]
        if len(self._last) < 3:
            return
        (t0, a), (t1, b), (t2, c) = self._last
        dt1, dt2 = t1 - t0, t2 - t1
        if 0.0 < dt1 <= self._max_gap_s and abs(dt2 - dt1) <= 1e-3:
            d2 = c - 2.0 * b + a
            self._sum += d2 * d2 / 6.0
            self._count += 1

    @property
    def sigma_rad(self) -> float:
        """The jitter's estimate (rad)."""
        n0 = JITTER_PRIOR_COUNT
        return math.sqrt((n0 * self._prior2 + self._sum) / (n0 + self._count))
