"""A share a drive's recent targets show, learned online: the running mean of their posterior
weights (one EM step a frame): the odd-object share (``learn_odd_share``) and the experimental
``learn_contact_spread``'s tight-reading share.

The share is ``(n₀·w₀ + Σ cᵢ·wᵢ)/(n₀ + Σ cᵢ)``: ``n₀`` pseudo-targets of the prior share ``w₀``,
each frame's targets' posterior weights ``wᵢ`` counting ``cᵢ = min(1, dt/τ)`` each (``dt`` the
time since the previous frame, ``τ`` = :data:`CORRELATION_TIME_S`: closer frames share their
errors; 1 in the first frame), the sums fading as ``exp(−dt/T)`` over a memory ``T``. Causal:
the share read before a frame's update is that of the frames before it.

Seconds.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

CORRELATION_TIME_S = 0.5
"""A track's frames closer than this share their errors (a car body's pitch mode is 1–1.5 Hz)."""


def fade(elapsed_s: float, memory_s: float) -> float:
    """How much of the evidence is left after ``elapsed_s`` (NaN: none before: 1)."""
    return math.exp(-max(elapsed_s, 0.0) / memory_s) if elapsed_s == elapsed_s else 1.0


class RecentShare:
    """The running share of a drive's recent targets (see the module).

    Args:
        prior_share: ``w₀``, the share before any target.
        prior_count: ``n₀``, its weight in targets.
        memory_s: ``T``, the time constant the evidence fades with, seconds.
    """

    def __init__(self, prior_share: float, prior_count: float, memory_s: float) -> None:
        self._prior_sum = prior_count * prior_share
        self._prior_count = prior_count
        self._memory_s = memory_s
        self.reset()

    def reset(self) -> None:
        """Forget the drive."""
        self._time_s = math.nan
        self._sum = 0.0
        self._count = 0.0

    @property
    def share(self) -> float:
        """The share so far."""
        return (self._prior_sum + self._sum) / (self._prior_count + self._count)

    def add(self, weights: FloatArray, time_s: float) -> None:
        """A frame's targets' posterior weights ``(n,)`` at ``time_s`` (s)."""
        elapsed_s = time_s - self._time_s
        left = fade(elapsed_s, self._memory_s)
        self._time_s = time_s
        each = (
            float(np.clip(elapsed_s / CORRELATION_TIME_S, 0.0, 1.0))
            if elapsed_s == elapsed_s
            else 1.0
        )
        self._sum = self._sum * left + each * float(np.sum(weights))
        self._count = self._count * left + each * weights.shape[0]
