"""The learned peer of the KITTI tracking evaluation (``--methods learned-peer``): a
gradient-boosting regressor from box features to distance, trained leave-one-sequence-out.

It is a yardstick, not an estimator: it knows nothing of the camera's height, the road or the
vehicle's size, only boxes and the distances that went with them on *other* drives. Each
sequence is scored by a model fitted on the scored (box, truth) pairs of every other sequence
under the same data folder, with the same box source and score threshold, never on its own.

Features (per box, intrinsics-normalised so that cameras with other focal lengths and principal
points read alike; ``f``, ``c_x``, ``c_y`` of the camera, pixels):

- the box edges relative to the principal point: ``(left − c_x)/f``, ``(top − c_y)/f``,
  ``(right − c_x)/f``, ``(bottom − c_y)/f``;
- its width ``w/f``, height ``h/f`` and aspect ``w/h``;
- the class as a vehicle-type code (``Car`` 0, ``Van`` 1, anything else 2; a class-blind
  detector's boxes are all ``Car``).

Model: scikit-learn's ``HistGradientBoostingRegressor`` with its default settings (not tuned
on these sequences), squared-error loss on the distance in metres (the RMSE the evaluation
reports), early stopping off and a fixed seed: deterministic. scikit-learn is the optional
extra ``learned`` (``pip install 'slopedist[learned]'``).
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slopedist.core.camera import Camera
from slopedist.core.errors import ConfigurationError, import_optional
from slopedist.io.detections.boxes import BoxTable

PEER_METHOD = "learned-peer"
"""Name of the learned peer in ``eval kitti-tracking --methods`` and ``report --methods``."""

PEER_SEED = 0
"""Seed of the regressor (with early stopping off it draws no random numbers; fixed anyway)."""

PEER_PROTOCOL = (
    "trained leave-one-sequence-out: each sequence is scored by a gradient-boosting regressor "
    "(scikit-learn HistGradientBoostingRegressor, default settings, seed 0) fitted on the "
    "matched boxes of every other sequence under the data folder, same box source and score "
    "threshold; features: intrinsics-normalised box edges, width, height, aspect and class; "
    "its distance refers to the truth's reference point"
)
"""How the peer is trained, for the protocol block of a report."""

FEATURE_NAMES = (
    "left_n",
    "top_n",
    "right_n",
    "bottom_n",
    "width_n",
    "height_n",
    "aspect",
    "vehicle_type",
)
"""Columns of :func:`box_features`, in order."""

_TYPE_CODES = {"car": 0.0, "van": 1.0}
_OTHER_TYPE = 2.0

FloatArray = NDArray[np.float64]


def box_features(boxes: BoxTable, camera: Camera) -> FloatArray:
    """The peer's features of every box, ``(N, len(FEATURE_NAMES))`` (see the module
    docstring; dimensionless except the class code)."""
    b = np.asarray(boxes.boxes, dtype=float).reshape(-1, 4)
    f = camera.f
    left, top = (b[:, 0] - camera.c_x) / f, (b[:, 1] - camera.c_y) / f
    right, bottom = (b[:, 2] - camera.c_x) / f, (b[:, 3] - camera.c_y) / f
    width, height = right - left, bottom - top
    with np.errstate(divide="ignore", invalid="ignore"):
        aspect = np.where(height > 0, width / height, np.nan)
    vtype = np.array(
        [_TYPE_CODES.get(str(c).strip().lower(), _OTHER_TYPE) for c in boxes.cls], dtype=float
    )
    return np.column_stack([left, top, right, bottom, width, height, aspect, vtype])


def regressor_class() -> Any:
    """scikit-learn's ``HistGradientBoostingRegressor``.

    Raises:
        OptionalDependencyError: scikit-learn (extra ``learned``) is not installed.
    """
    module = import_optional(
        "sklearn.ensemble", "learned", "the learned-peer row (gradient boosting)"
    )
    return module.HistGradientBoostingRegressor


def usable_pairs(features: FloatArray, distance_m: FloatArray) -> NDArray[np.bool_]:
    """Per training pair (``features`` rows ``(n, k)``, ``distance_m`` ``(n,)`` metres): whether
    :func:`fit_peer` learns from it (every feature finite, a finite distance > 0)."""
    y = np.asarray(distance_m, dtype=float)
    return np.isfinite(np.asarray(features, dtype=float)).all(axis=1) & np.isfinite(y) & (y > 0)


def fit_peer(features: FloatArray, distance_m: FloatArray, seed: int = PEER_SEED) -> Any:
    """A gradient-boosting regressor fitted to ``distance_m`` (metres) from ``features``
    (:func:`box_features` rows); rows :func:`usable_pairs` refuses are left out.

    Raises:
        OptionalDependencyError: scikit-learn is not installed.
        ConfigurationError: no usable training row.
    """
    x = np.asarray(features, dtype=float)
    y = np.asarray(distance_m, dtype=float)
    keep = usable_pairs(x, y)
    if not keep.any():
        raise ConfigurationError("the learned peer has no usable training pair")
    model = regressor_class()(early_stopping=False, random_state=seed)
    model.fit(x[keep], y[keep])
    return model


@dataclass(frozen=True)
class PeerSamples:
    """One sequence's training pairs: :func:`box_features` rows and their true distances (m)."""

    features: FloatArray
    distance_m: FloatArray

    def __len__(self) -> int:
        return int(self.distance_m.shape[0])

    @property
    def usable(self) -> int:
        """Pairs :func:`fit_peer` can learn from (finite features, a finite distance > 0)."""
        if not len(self):
            return 0
        x = np.asarray(self.features, dtype=float).reshape(len(self), -1)
        return int(np.sum(usable_pairs(x, self.distance_m)))


class LeaveOneSequenceOut:
    """The peer of each sequence, fitted on the pairs of all the others (fitted on first use,
    then kept).

    Args:
        samples: per sequence name, its training pairs (every sequence under the data folder,
            whether or not it is scored).
        seed: the regressor's seed.

    Attributes:
        fit_seconds: wall time spent fitting, seconds (all folds so far).
    """

    def __init__(self, samples: Mapping[str, PeerSamples], seed: int = PEER_SEED) -> None:
        self.samples = dict(samples)
        self.seed = seed
        self.fit_seconds = 0.0
        self._models: dict[str, Any] = {}

    def training_sequences(self, held_out: str) -> list[str]:
        """The sequences the model of ``held_out`` is fitted on (every other one with a usable
        pair: one whose pairs are all unusable would leave the fit empty)."""
        return [s for s, p in self.samples.items() if s != held_out and p.usable]

    def model(self, held_out: str) -> Any:
        """The model that never saw ``held_out``.

        Raises:
            ConfigurationError: no other sequence has training pairs.
        """
        if held_out not in self._models:
            names = self.training_sequences(held_out)
            if not names:
                raise ConfigurationError(
                    f"the learned peer of sequence {held_out} has no other sequence to train on"
                )
            t0 = time.perf_counter()
            self._models[held_out] = fit_peer(
                np.concatenate([self.samples[s].features for s in names]),
                np.concatenate([self.samples[s].distance_m for s in names]),
                self.seed,
            )
            self.fit_seconds += time.perf_counter() - t0
        return self._models[held_out]

    def predict(self, held_out: str, features: FloatArray) -> FloatArray:
        """Distances (metres) of ``features`` rows of sequence ``held_out``; NaN for a row with
        a non-finite feature."""
        x = np.asarray(features, dtype=float)
        out = np.full(x.shape[0], np.nan)
        ok = np.isfinite(x).all(axis=1)
        if ok.any():
            out[ok] = self.model(held_out).predict(x[ok])
        return out
