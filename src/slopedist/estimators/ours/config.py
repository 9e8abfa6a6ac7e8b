"""Options of ``ours``: the ten a user sets (:class:`OursConfig`) and the experimental settings
the benchmarks vary (:class:`OursAblation`: the switches of the ablation and the model's physical
constants), and their ``KEY=VALUE`` texts (``--ours-option``).

Convention: camera x right, y down, z forward; metres, seconds, radians, pixels.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from slopedist.core.errors import ConfigurationError
from slopedist.core.suggest import close_match, did_you_mean
from slopedist.core.textfiles import parse_bool
from slopedist.estimators.base import ReferencePoint
from slopedist.estimators.ours import filter as kf
from slopedist.estimators.ours.fusion import SizeMode
from slopedist.estimators.ours.priors import VEHICLE_TYPE_MIXTURE, DimensionPrior, YawPrior
from slopedist.estimators.ours.selfcal import SelfCalConfig
from slopedist.io.detections.boxes import class_key

REFERENCES = (ReferencePoint.CENTRE, ReferencePoint.NEAREST_FACE, ReferencePoint.CONTACT)
"""The reference points ``ours`` can report in ``distance_m`` (option ``reference``): the
vehicle's centre (KITTI's z), its nearest face, or its contact point (the ground under the
nearest face: the same longitudinal distance as the nearest face)."""


def _is_number(value: object) -> bool:
    """Whether ``value`` is a real number (an int or a float, numpy's too; not a bool)."""
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(
        value, (bool, np.bool_)
    )


def _check_kinds(settings: object, what: str, positive: Iterable[str]) -> None:
    """The checks every option kind of a settings dataclass shares: booleans are booleans, the
    ``positive`` fields finite numbers > 0, the optional times None or such a number."""
    for f in fields(settings):  # type: ignore[arg-type]
        value = getattr(settings, f.name)
        if str(f.type) == "bool" and not isinstance(value, (bool, np.bool_)):
            raise ConfigurationError(f"{what} {f.name} must be true or false, got {value!r}")
        optional = str(f.type) == "float | None" and value is not None
        if optional and not (_is_number(value) and math.isfinite(value) and value > 0):
            raise ConfigurationError(f"{what} {f.name} must be a finite number > 0, got {value!r}")
    for name in positive:
        value = getattr(settings, name)
        if not (_is_number(value) and math.isfinite(value) and value > 0):
            raise ConfigurationError(f"{what} {name} must be a finite number > 0, got {value!r}")


@dataclass(frozen=True)
class OursConfig:
    """The options of ``ours`` (``--ours-option KEY=VALUE``, ``--reference``,
    ``--generic-class``; docs/method.md gives each with its unit, default and what it trades).

    The defaults are physical priors set without looking at evaluation results, except
    ``box_sigma_px``, fitted on the labels of the 13 shared KITTI tracking sequences (the spread
    of the labels' 2D box edges around their 3D boxes' projection, never a distance error:
    :func:`~slopedist.estimators.ours.prior_fitting.fit_parameters`).

    Attributes:
        box_sigma_px: pixel noise of a box edge (0.31 px: the labels' boxes are their 3D
            boxes' projections, rounded; a 3D detector's boxes, e.g. PointRCNN's, are
            projections of its own 3D boxes, whose errors act through the size and heading
            priors rather than as pixel noise; an image detector's are noisier).
        gradient_sigma_rad: prior spread of a target's road gradient relative to the ego's
            (1°): how far the ground contact, which assumes the target on the ego's road
            plane, is trusted.
        height_sigma_m: camera-height uncertainty (when not self-calibrating).
        mount_sigma_rad: mount-angle uncertainty (when not self-calibrating).
        max_age_s: a track unseen for longer is dropped (its vehicle starts afresh).
        max_relative_sigma: a box whose 1σ (``sigma_m``) exceeds this share of its distance is
            ``missing``, reason ``too_uncertain``, not ``ok`` (0.5: a 1σ interval of ±50 % is
            no distance to act on; a round bound, not fitted: no scored box of the 13 KITTI
            sequences comes near it with any box source, the largest being 0.40); the cue
            columns keep their values.
        size_learning: learn each track's own size (an isotropic scale of its class prior's
            dimensions, with its variance) from the frames where the ground contact is
            reliable, and use it in the size cues (:mod:`~slopedist.estimators.ours.
            size_learning`; record columns ``size_scale``, ``size_log_sigma``,
            ``track_height_m``).
        reference: the point of the vehicle ``distance_m`` refers to: ``centre`` (KITTI's z,
            the default), ``nearest_face`` or ``contact`` (the ground under the nearest face,
            the same longitudinal distance); the records carry ``distance_centre_m`` and
            ``distance_nearest_face_m`` whatever it is.
        generic_classes: class names that do not name the vehicle type, e.g. ``("Car",)`` for
            a class-blind detector that calls vans, trucks and buses ``Car`` (PointRCNN's and
            RRC's boxes; ``slopedist eval kitti-tracking --generic-class`` sets it for detector
            boxes, ``slopedist run/estimate --generic-class NAME`` to NAME; compared without
            regard to case): their size cues are read under a mixture of vehicle types
            (:mod:`~slopedist.estimators.ours.vehicle_types`).
        generic_sigma_only: read ``generic_classes`` as generic for the σ only: their
            distances are those of the class as given (as without ``generic_classes``), and
            their ``sigma_m`` adds the size error of the vehicle types they may be, weighed by
            the cue gap, in the share the size cues have in the fused distance
            (:func:`~slopedist.estimators.ours.vehicle_types.sigma_log_var`; a class-blind
            detector's vans and trucks are a size error the track cannot average). Without
            ``generic_classes`` it does nothing.
    """

    box_sigma_px: float = 0.31
    gradient_sigma_rad: float = math.radians(1.0)
    height_sigma_m: float = 0.03
    mount_sigma_rad: float = math.radians(0.2)
    max_age_s: float = 1.0
    max_relative_sigma: float = 0.5
    size_learning: bool = False
    reference: str = "centre"
    generic_classes: tuple[str, ...] = ()
    generic_sigma_only: bool = False

    def __post_init__(self) -> None:
        positive = ("box_sigma_px", "gradient_sigma_rad", "height_sigma_m", "mount_sigma_rad")
        _check_kinds(self, "ours option", (*positive, "max_age_s", "max_relative_sigma"))
        if self.reference not in {r.value for r in REFERENCES}:
            raise ConfigurationError(
                f"ours option reference must be one of "
                f"{', '.join(r.value for r in REFERENCES)}, got {self.reference!r}"
            )
        if isinstance(self.generic_classes, str):  # tuple("Car") would be ("C", "a", "r")
            raise ConfigurationError(
                f"ours option generic_classes must be a collection of class names, got the "
                f"text {self.generic_classes!r} (write ({self.generic_classes!r},))"
            )


@dataclass(frozen=True)
class OursAblation:
    """Experimental settings of ``ours`` for the benchmarks: the switches that turn parts of
    the method off (the ablation of ``benchmarks/ours_kitti.py``) and the model's physical
    constants (its sensitivity study halves and doubles them). ``--ours-option`` takes them too,
    as experimental keys: they may change or go without notice.

    The defaults are physical priors set without looking at evaluation results, except
    ``yaw_prior``, fitted on the headings of the labels of the 13 shared KITTI tracking
    sequences (:func:`~slopedist.estimators.ours.prior_fitting.fit_parameters`, never a
    distance error); ``benchmarks/ours_kitti.py`` reports the figures with each sequence scored
    under the fit on the other twelve.

    Attributes:
        use_width: use the box-width cue.
        yaw_hypotheses: consider headings other than ψ = 0.
        use_ground_contact: fuse the ground-contact cue.
        gradient_feedback: use each target's continuous road gradient α (estimated over its
            track from Δy and the size distance) in its ground-contact cue, instead of the prior
            α ~ N(0, ``gradient_sigma_rad``). α is estimated and reported either way.
        motion_model: filter the distance over time (constant velocity; speed and TTC).
        yaw_memory: carry each track's heading belief over frames (tempered evidence).
        self_calibrate: estimate θ0 and h online (``ours-selfcal`` sets it).
        adapt_contact_trust: scale the target-gradient prior's and the horizon jitter's
            variances (KITTI's) by how rough the drive's road is against KITTI's, read from the
            ego's own gradient history (:mod:`~slopedist.estimators.ours.road_roughness`): on a
            flat road the ground contact is trusted more, on a rough one less (not kept: on KITTI
            the ego's road does not tell the targets' contact scatter; docs/detector_boxes.md).
        learn_contact_angle: scale the target-gradient prior's and the mount's variances by the
            drive's ground-contact angle error, read from each track's cues as its distance
            changes (:mod:`~slopedist.estimators.ours.contact_angle`).
        learn_contact_spread: read each target twice, with the ground contact at the drive's
            own angle spread (from how the gap between all its targets' cues depends on their
            distance) and at the configured one, and mix the two by how well each explains the
            target's cues and how often it explained the drive's recent targets
            (:mod:`~slopedist.estimators.ours.contact_spread`).
        learn_odd_share: learn the drive's share of odd-object boxes (``odd_object_weight``
            its prior) online from the targets' posterior odd probabilities
            (:class:`~slopedist.estimators.ours.odd_objects.OddShare`): a box source whose
            boxes fit their vehicles loosely is read as such after a few seconds. False keeps
            the share at ``odd_object_weight``.
        learn_horizon_jitter: estimate the horizon jitter (``theta_sigma_rad`` its prior)
            online from the second differences of the measured θ
            (:class:`~slopedist.estimators.ours.road_roughness.HorizonJitter`).
        adapt_box_noise: estimate the box-edge noise online from the second differences of the
            tracks' box edges (10 Hz tracks are smooth, so what is left is detector noise),
            with ``box_sigma_px`` as its prior.
        censor_border_cuts: a cue whose box edge touches the image border also bounds the
            distance from above (a box cut by the border is smaller than its vehicle, so its
            size cue says at least as far as the vehicle is, and a cut bottom hides the ground
            contact below the image): :func:`~slopedist.estimators.ours.fusion.censor_upper`.
        occlusion_aware: a box with an edge on a nearer target's box (its bottom lower in the
            image) may show only part of its vehicle (a box drawn around what is visible): its
            width or height cue, if it says farther than the ground contact by more than their
            noise explains, gets that excess as extra variance
            (:func:`~slopedist.estimators.ours.occlusion.hidden_sides`,
            :func:`~slopedist.estimators.ours.occlusion.occlusion_log_var`), so the fusion
            leans on the ground contact (and the self-calibration, which uses the size cue).
        road_bend_sigma: ``sigma_m`` adds the height cue's error from the camera height above
            the target's road, which a road bending between the ego and the target (the foot of
            a hill) changes by ``Z_n·(tan α − tan α̂)``
            (:mod:`~slopedist.estimators.ours.road_bend`); the distances stay as they are.
        theta_sigma_rad: per-frame jitter of the ego gradient's vanishing line.
        no_rotation_theta_sigma_rad: the same when the frame has no rotation (θ of a camera at
            rest is used then).
        rate_sigma_per_s: prior spread of the relative rate Ż/Z of a new track.
        yaw_prior: heading prior (fitted, see above).
        atypical_height_weight: prior probability that a vehicle's height is atypical for its
            class (a sports car, a pick-up or a box van labelled ``Car``); 0 turns it off.
        atypical_height_factor: how much wider the height spread of such a vehicle is.
        odd_object_weight: prior probability that a box holds an **odd object**, one whose
            size is not its class's at all (a concrete block, a covered trailer, a vehicle
            partly hidden, boxed as ``Car``): 2.8 %, the share of ``Misc`` among the vehicle
            labels of the KITTI object detection training set (973 of 34 234 Car, Van, Truck,
            Tram and Misc; Geiger, Lenz, Urtasun, CVPR 2012), the published frequency of
            street objects a vehicle detector boxes that have no vehicle class's size. 0 turns
            it off. In that mode the size cues barely constrain the distance, so where they
            disagree with the ground contact by more than the class's spread explains, the
            posterior moves to it and the fusion follows the ground contact (record column
            ``odd_size_prob``; :class:`~slopedist.estimators.ours.fusion.SizeMode`). Not used
            for a generic class (whose vehicle-type mixture covers odd vehicles), nor for a box
            whose detector gives its size (a measured size is the vehicle's; nor is
            ``atypical_height_weight``).
        odd_object_log_sigma: the relative spread (of the logarithm) of an odd object's height
            and width: 0.5, objects from 0.5 m to 4 m tall (a block to a truck) read as ±2σ
            about the class's size (physical, not fitted).
        yaw_evidence_weight: weight (0–1] of one frame's heading evidence in a track's belief
            (consecutive frames are not independent evidence).
        yaw_memory_s: time constant with which a track's heading belief relaxes to the prior.
        process: process noise of the filters.
        min_iou: IoU needed to continue an id-less track.
        gate_sigma: a box further than this many σ from its track's prediction starts a new
            track.
        truncation_factor: noise multiplier of a cue whose box edge touches the image border
            (it keeps a weak weight, so that a box cut on every side still gets a distance).
        occlusion_gate_sigma: the outlier test of the occlusion check, in standard deviations
            (3, the usual test): of the two cues' noise for the excess, of the box-edge noise
            for an edge touching a nearer box.
        consistency_gate_sigma: the cue consistency check's threshold, in standard deviations
            of the gap between the size cues and the ground contact (3, the usual outlier
            test, as ``occlusion_gate_sigma``; not fitted): beyond it the measurement's
            variance covers both cues (record column ``cue_gap_sigma``).
        noise_time_s: the time over which each track measures the frame-to-frame noise its
            measurements show (the running mean of its filter's normalised innovations),
            which widens the σ of its speed and time to collision, seconds (1: the ego
            gradient's look-back; None: the nominal noise throughout).
        size_evidence_time_s: the time τ over which a track's ground-contact evidence about
            its size is one independent observation (consecutive frames share the target
            road's gradient error): a frame's evidence weighs ``min(1, dt/τ)``. None (the
            default): the time the target gradient's random walk takes to wander by its prior
            spread, ``(gradient_sigma_rad / process.gradient_rad)²`` = 4 s with the physical
            defaults (nothing fitted; :func:`size_evidence_time`).
        priors: class → dimension prior (None = the built-in table).
        type_mixture: vehicle types ``(name, prior, weight)`` behind a generic class
            (default the published frequencies of
            :data:`~slopedist.estimators.ours.priors.VEHICLE_TYPE_MIXTURE`).
        selfcal: self-calibration priors and noise levels.
    """

    use_width: bool = True
    yaw_hypotheses: bool = True
    use_ground_contact: bool = True
    gradient_feedback: bool = False
    motion_model: bool = True
    yaw_memory: bool = False
    self_calibrate: bool = False
    adapt_box_noise: bool = False
    adapt_contact_trust: bool = False
    learn_contact_angle: bool = False
    learn_horizon_jitter: bool = False
    learn_contact_spread: bool = False
    learn_odd_share: bool = True
    censor_border_cuts: bool = True
    occlusion_aware: bool = True
    road_bend_sigma: bool = True
    theta_sigma_rad: float = math.radians(0.3)
    no_rotation_theta_sigma_rad: float = math.radians(1.0)
    rate_sigma_per_s: float = 0.5
    yaw_prior: YawPrior = field(default_factory=YawPrior)
    atypical_height_weight: float = 0.0
    atypical_height_factor: float = 3.0
    odd_object_weight: float = 0.028
    odd_object_log_sigma: float = 0.5
    yaw_evidence_weight: float = 0.3
    yaw_memory_s: float = 2.0
    process: kf.ProcessNoise = field(default_factory=kf.ProcessNoise)
    min_iou: float = 0.3
    gate_sigma: float = 5.0
    truncation_factor: float = 10.0
    occlusion_gate_sigma: float = 3.0
    consistency_gate_sigma: float = 3.0
    noise_time_s: float | None = 1.0
    size_evidence_time_s: float | None = None
    priors: dict[str, DimensionPrior] | None = None
    type_mixture: tuple[tuple[str, DimensionPrior, float], ...] = VEHICLE_TYPE_MIXTURE
    selfcal: SelfCalConfig = field(default_factory=SelfCalConfig)

    def __post_init__(self) -> None:
        positive = (
            "theta_sigma_rad",
            "no_rotation_theta_sigma_rad",
            "rate_sigma_per_s",
            "yaw_memory_s",
            "gate_sigma",
            "truncation_factor",
            "yaw_evidence_weight",
            "occlusion_gate_sigma",
            "consistency_gate_sigma",
            "odd_object_log_sigma",
            "atypical_height_factor",
        )
        _check_kinds(self, "ours option", positive)
        if self.yaw_evidence_weight > 1:
            raise ConfigurationError(
                "ours option yaw_evidence_weight must be in (0, 1], got "
                f"{self.yaw_evidence_weight!r}"
            )
        rare = (self.atypical_height_weight, self.odd_object_weight)
        if not (all(_is_number(w) and 0.0 <= w < 1.0 for w in rare) and sum(rare) < 1.0):
            raise ConfigurationError(
                f"ours options atypical_height_weight and odd_object_weight must be in [0, 1) "
                f"with a sum below 1, got {rare[0]!r} and {rare[1]!r}"
            )
        if not (_is_number(self.min_iou) and 0.0 <= self.min_iou <= 1.0):
            raise ConfigurationError(f"ours option min_iou must be in [0, 1], got {self.min_iou!r}")

    @property
    def size_modes(self) -> list[tuple[SizeMode, float]]:
        """The size modes of a class with their prior probabilities: the typical vehicle, and
        where their weights are above 0 the atypical height and the odd object."""
        rare = [
            (SizeMode(height_factor=self.atypical_height_factor), self.atypical_height_weight),
            (SizeMode(log_sigma_floor=self.odd_object_log_sigma), self.odd_object_weight),
        ]
        typical = 1.0 - sum(w for _, w in rare)
        return [(SizeMode(), typical)] + [(m, w) for m, w in rare if w > 0]


def size_evidence_time(config: OursConfig, ablation: OursAblation) -> float:
    """τ of ``size_evidence_time_s``, seconds (derived from the gradient priors when it is
    None)."""
    if ablation.size_evidence_time_s is not None:
        return float(ablation.size_evidence_time_s)
    return (config.gradient_sigma_rad / ablation.process.gradient_rad) ** 2


def carries_state(config: OursConfig, ablation: OursAblation) -> bool:
    """Whether any state is carried from frame to frame (so boxes must be associated)."""
    return (
        ablation.motion_model
        or ablation.yaw_memory
        or ablation.gradient_feedback
        or ablation.adapt_box_noise
        or config.size_learning
    )


USER_OPTIONS = tuple(f.name for f in fields(OursConfig))
"""The options of :class:`OursConfig`, the ones a user sets."""

EXPERIMENTAL_OPTIONS = tuple(f.name for f in fields(OursAblation))
"""The settings of :class:`OursAblation`, experimental."""


def configs_of(
    options: Mapping[str, Any],
    config: OursConfig | None = None,
    ablation: OursAblation | None = None,
) -> tuple[OursConfig, OursAblation]:
    """``config`` and ``ablation`` (default: the defaults) with ``options`` set, each key
    where it belongs (a user option or an experimental one).

    Raises:
        ConfigurationError: an unknown key (the message lists the known ones), or a value out
            of range.
    """
    unknown = sorted(set(options) - set(USER_OPTIONS) - set(EXPERIMENTAL_OPTIONS))
    if unknown:
        hint = did_you_mean(unknown[0], [*USER_OPTIONS, *EXPERIMENTAL_OPTIONS])
        raise ConfigurationError(
            f"unknown option(s) for method 'ours': {', '.join(unknown)}{hint} "
            f"(known: {', '.join(sorted(USER_OPTIONS))}; experimental: "
            f"{', '.join(sorted(EXPERIMENTAL_OPTIONS))})"
        )
    user = {k: v for k, v in options.items() if k in USER_OPTIONS}
    experimental = {k: v for k, v in options.items() if k in EXPERIMENTAL_OPTIONS}
    return (
        replace(config or OursConfig(), **user),
        replace(ablation or OursAblation(), **experimental),
    )


def unscored_generic_class(
    generic_classes: Iterable[str], vehicle_classes: Iterable[str]
) -> str | None:
    """The first of ``generic_classes`` that is not one of ``vehicle_classes`` (compared as
    :func:`~slopedist.io.detections.boxes.class_key`: its boxes get no distance), None when all
    are."""
    vehicles = {class_key(c) for c in vehicle_classes}
    return next((c for c in generic_classes if class_key(c) not in vehicles), None)


def idle_sigma_only(
    ours_options: Iterable[tuple[str, Any]], generic_classes: Iterable[str]
) -> bool:
    """Whether ``ours_options`` set ``generic_sigma_only`` true with no generic class to apply
    it to (it would do nothing)."""
    return bool(dict(ours_options).get("generic_sigma_only")) and not tuple(generic_classes)


def _parse_float(text: str) -> float:
    """A finite number."""
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(text)
    return value


def _parse_optional_float(text: str) -> float | None:
    """A finite number, or ``none`` for None."""
    return None if text.strip().lower() == "none" else _parse_float(text)


_OPTION_PARSERS = {
    "bool": parse_bool,
    "float": _parse_float,
    "float | None": _parse_optional_float,
}
"""How a ``KEY=VALUE`` text becomes each settable kind of option (by its annotation); options
of other kinds (priors, mixtures, nested settings, and ``reference`` and ``generic_classes``,
which have options of their own) are not set this way."""

_KINDS = {f.name: str(f.type) for f in (*fields(OursConfig), *fields(OursAblation))}
"""Each option's kind (its annotation)."""


OWN_OPTIONS = {
    "reference": "--reference (a batch manifest: column reference)",
    "generic_classes": "--generic-class NAME, repeatable (a batch manifest: column "
    "generic_classes)",
}
"""The fields that have an option of their own, with it (named when ``KEY=VALUE`` gives one)."""


def _settable(names: Iterable[str]) -> list[str]:
    """Those of ``names`` that ``KEY=VALUE`` sets (sorted)."""
    return sorted(n for n in names if _KINDS[n] in _OPTION_PARSERS and n not in OWN_OPTIONS)


def user_options() -> list[str]:
    """The options of :class:`OursConfig` that :func:`parse_option` sets (sorted)."""
    return _settable(USER_OPTIONS)


def experimental_options() -> list[str]:
    """The settings of :class:`OursAblation` that :func:`parse_option` sets (sorted)."""
    return _settable(EXPERIMENTAL_OPTIONS)


def settable_options() -> list[str]:
    """Every key :func:`parse_option` sets: :func:`user_options` and
    :func:`experimental_options` (sorted)."""
    return sorted(user_options() + experimental_options())


def parse_option(text: str) -> tuple[str, bool | float | None]:
    """``KEY=VALUE`` (e.g. ``box_sigma_px=1.0``, ``size_learning=true``, or an experimental
    ``odd_object_weight=0``) as an option and its value; the value is checked with the whole
    configuration's rules (:func:`configs_of`).

    Raises:
        ConfigurationError: not ``KEY=VALUE``, a key that is no settable option (the message
            lists them), or a value of the wrong kind or out of range.
    """
    key, sep, value = (part.strip() for part in text.partition("="))
    if not sep or not key:
        raise ConfigurationError(f"'{text}' is not KEY=VALUE")
    if key in OWN_OPTIONS:
        raise ConfigurationError(f"'{key}' is not set as KEY=VALUE: use {OWN_OPTIONS[key]}")
    parser = _OPTION_PARSERS.get(_KINDS.get(key, ""))
    if parser is None:
        match = close_match(key, [*user_options(), *experimental_options()])
        hint = f" (did you mean '{match}'?)" if match else ""
        raise ConfigurationError(
            f"'{key}' is not an ours option settable here{hint}; choose from "
            f"{', '.join(user_options())} (experimental, for the benchmarks: "
            f"{', '.join(experimental_options())})"
        )
    try:
        parsed = parser(value)
    except ValueError:
        raise ConfigurationError(f"ours option {key}: '{value}' is not a {_KINDS[key]}") from None
    configs_of({key: parsed})  # the range checks
    return key, parsed


OPTION_SEPARATOR = ";"
"""Separator of the options in one text (a batch manifest's ``ours_options`` cell:
``box_sigma_px=1;size_learning=true``); no option value contains it, nor a comma."""


def parse_options(texts: Iterable[str]) -> tuple[tuple[str, bool | float | None], ...]:
    """Several ``KEY=VALUE`` texts (:func:`parse_option` each), in their order.

    Raises:
        ConfigurationError: a bad text (:func:`parse_option`), a key given twice, or values
            that do not go together (e.g. rare-size weights summing to 1 or more).
    """
    pairs = tuple(parse_option(text) for text in texts)
    keys = [key for key, _ in pairs]
    twice = sorted({key for key in keys if keys.count(key) > 1})
    if twice:
        raise ConfigurationError(f"ours option {', '.join(twice)} given more than once")
    configs_of(dict(pairs))  # the rules across options
    return pairs


def parse_option_list(text: str) -> tuple[tuple[str, bool | float | None], ...]:
    """``KEY=VALUE`` options separated by :data:`OPTION_SEPARATOR` (spaces and empty items
    ignored: ``"a=1; b=true;"``) as ``(key, value)`` pairs (:func:`parse_options`).

    Raises:
        ConfigurationError: a comma (the separator is ``;``), a bad option or a key given twice.
    """
    if "," in text:
        raise ConfigurationError(
            f"'{text}': separate ours options with '{OPTION_SEPARATOR}', "
            "e.g. box_sigma_px=1;size_learning=true"
        )
    return parse_options(item for item in text.split(OPTION_SEPARATOR) if item.strip())
