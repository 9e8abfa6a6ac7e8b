"""The options of the distance methods: which methods (``--method(s)``, ``--offline``) and the
estimators' settings (``--alphas``, ``--thresholds``, ``--reference``, ``--ours-option``, the
``depthmap`` sampling), handed to a command as one
:class:`~slopedist.estimators.EstimatorConfig`."""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable
from typing import Any

import click

from slopedist.cli.choice import Choice
from slopedist.cli.options import apply_options, split_list
from slopedist.core.errors import ConfigurationError
from slopedist.core.suggest import did_you_mean
from slopedist.estimators import (
    ESTIMATORS,
    OFFLINE_COUNTERPARTS,
    EstimatorConfig,
    available_methods,
    idle_sigma_only,
    takes_ours_options,
    unscored_generic_class,
    with_offline,
)
from slopedist.estimators import parse_ours_options as ours_option_pairs
from slopedist.estimators.base import VEHICLE_REFERENCES, ReferencePoint
from slopedist.estimators.depthmap import DepthSample, DepthScaling
from slopedist.estimators.references import DEFAULT_REFERENCE
from slopedist.evaluation.learned_peer import PEER_METHOD


def check_methods(names: list[str], evaluation: bool = False) -> list[str]:
    """Fail with a usage error on an unknown method name (``evaluation``: the evaluation-only
    rows, such as the learned peer, are known too)."""
    known = available_methods() + ([PEER_METHOD] if evaluation else [])
    bad = [n for n in names if n not in known]
    if bad:
        named = f"method '{bad[0]}'{did_you_mean(bad[0], known)}" if len(bad) == 1 else ""
        raise click.BadParameter(
            f"unknown {named or 'methods ' + ', '.join(bad)} (choose from {', '.join(known)})",
            param_hint="--methods/--method",
        )
    return names


offline_option = click.option(
    "--offline",
    is_flag=True,
    help="Also the offline mode of each method that has one (ours → ours-offline: smoothed "
    "over the whole drive, for log analysis; reported under its own name, never mixed with "
    "the causal method).",
)


def with_offline_methods(names: list[str]) -> list[str]:
    """``names`` with their offline counterparts (``--offline``: ``ours`` → ``ours,
    ours-offline``); a usage error when none of them has an offline mode, rather than a run
    without the offline figures asked for."""
    out = with_offline(names)
    if not any(getattr(ESTIMATORS.get(m), "offline", False) for m in out):
        raise click.UsageError(
            f"--offline: none of the methods ({', '.join(names)}) has an offline mode; add "
            f"one to --methods (methods with one: {', '.join(OFFLINE_COUNTERPARTS)})"
        )
    return out


def evaluation_method_options(
    config: EstimatorConfig, names: list[str]
) -> dict[str, dict[str, Any]]:
    """The constructor options of an evaluation's estimators (of every method when ``names``
    is empty; the evaluation-only rows have none)."""
    estimators = [n for n in names if n != PEER_METHOD]
    return config.method_options(estimators if names else available_methods())


alphas_option = click.option(
    "--alphas",
    default="3,5,6",
    show_default=True,
    help="paper, imu: angle steps α1,α2,α3 in degrees (eq. 7).",
)
thresholds_option = click.option(
    "--thresholds",
    default="0,-10,-20",
    show_default=True,
    help="paper, imu: Δy thresholds in pixels for α1,α2,α3 (eq. 7).",
)

reference_option = click.option(
    "--reference",
    type=Choice([r.value for r in VEHICLE_REFERENCES]),
    default=None,
    help="The point of the vehicle distance_m refers to, for every method [run, estimate, "
    f"batch: {DEFAULT_REFERENCE.value}, the gap; an evaluation: its truth's, "
    "--gt-reference, as ours reports it].",
)


def user_reference(config: EstimatorConfig) -> tuple[EstimatorConfig, ReferencePoint]:
    """The point a command's user sees distances at (``--reference``, else
    :data:`~slopedist.estimators.references.DEFAULT_REFERENCE`) and ``config`` without it:
    each method then reports its own point, and the frame step moves every method's
    distances to the one asked for (:class:`~slopedist.streaming.step.FrameStep`)."""
    wanted = ReferencePoint(config.reference) if config.reference else DEFAULT_REFERENCE
    return dataclasses.replace(config, reference=None), wanted


ours_option = click.option(
    "--ours-option",
    "ours_options",
    multiple=True,
    metavar="KEY=VALUE",
    help="ours, ours-selfcal, ours-offline: set one of its options, e.g. box_sigma_px=1.0 or "
    "size_learning=true (repeatable; docs/method.md lists them; the ablation's keys, e.g. "
    "odd_object_weight=0, are taken too, as experimental settings for benchmarks).",
)


def _generic_class_names(
    ctx: click.Context, param: click.Parameter, value: tuple[str, ...]
) -> tuple[str, ...]:
    names = tuple(v.strip() for v in value)
    if not all(names):
        raise click.BadParameter("names no class; give a class name", param_hint="--generic-class")
    return names


generic_class_option = click.option(
    "--generic-class",
    "generic_classes",
    multiple=True,
    metavar="NAME",
    callback=_generic_class_names,
    help="ours, ours-selfcal, ours-offline: a class name the detector gives to any vehicle "
    "type (a class-blind detector's 'car' for vans, trucks and buses too; case-insensitive): "
    "ours reads it as a mixture of car/van/truck/bus (with --ours-option "
    "generic_sigma_only=true in the σ only). Repeatable.",
)


def ours_config(
    config: EstimatorConfig,
    method: str,
    generic_classes: tuple[str, ...],
    vehicle_classes: tuple[str, ...],
) -> EstimatorConfig:
    """``config`` for ``method`` with the ``--generic-class`` names ``generic_classes``; a usage
    error for a generic class given to a method that is not ``ours`` or built on it, a generic
    class that is not one of ``vehicle_classes`` (its boxes are not estimated), or
    ``--ours-option generic_sigma_only=true`` without a generic class (it would do nothing)."""
    ours = takes_ours_options(method)
    if generic_classes and not ours:
        methods = ", ".join(m for m in available_methods() if takes_ours_options(m))
        raise click.UsageError(
            f"--generic-class is for methods {methods}; the method is '{method}'"
        )
    unscored = unscored_generic_class(generic_classes, vehicle_classes)
    if unscored is not None:
        raise click.UsageError(
            f"--generic-class {unscored}: not one of --vehicle-classes "
            f"({', '.join(vehicle_classes)}), so its boxes get no distance; add it there"
        )
    if ours and idle_sigma_only(config.ours_options, generic_classes):
        raise click.UsageError(
            "--ours-option generic_sigma_only=true applies to generic classes and none is "
            "given: name the class your detector gives to any vehicle with --generic-class "
            "NAME (e.g. --generic-class car)"
        )
    return dataclasses.replace(config.with_method(method), generic_classes=generic_classes)


def parse_ours_options(texts: tuple[str, ...]) -> tuple[tuple[str, Any], ...]:
    """``--ours-option KEY=VALUE`` values as ``(name, value)`` pairs (usage errors name the
    option)."""
    try:
        return ours_option_pairs(texts)
    except ConfigurationError as exc:
        raise click.BadParameter(str(exc), param_hint="--ours-option") from None


def parse_triple(value: str, name: str) -> tuple[float, float, float]:
    """Parse ``"a,b,c"`` into three floats or fail with a usage error naming ``name``."""
    parts = split_list(value) or []
    try:
        nums = tuple(float(p) for p in parts)
    except ValueError:
        raise click.BadParameter(
            f"'{value}' is not three comma-separated numbers", param_hint=name
        ) from None
    if len(nums) != 3:
        raise click.BadParameter(f"expected three numbers, got {len(nums)}", param_hint=name)
    if not all(math.isfinite(n) for n in nums):
        raise click.BadParameter(f"'{value}' is not three finite numbers", param_hint=name)
    return nums[0], nums[1], nums[2]


def estimator_config(
    alphas: str = "3,5,6",
    thresholds: str = "0,-10,-20",
    depth_sample: str = DepthSample.CENTRE.value,
    depth_window: int = 5,
    depth_scaling: str = DepthScaling.NONE.value,
    method: str | None = None,
    reference: str | None = None,
    ours_options: tuple[tuple[str, Any], ...] = (),
) -> EstimatorConfig:
    """The :class:`~slopedist.estimators.EstimatorConfig` of the command-line strings (usage
    errors name the option)."""
    a = parse_triple(alphas, "--alphas")
    t = parse_triple(thresholds, "--thresholds")
    if not (t[0] > t[1] > t[2]):
        raise click.BadParameter(
            "thresholds must decrease (t1 > t2 > t3)", param_hint="--thresholds"
        )
    try:
        config = EstimatorConfig(
            alphas_deg=a,
            thresholds_px=t,
            depth_sample=DepthSample(depth_sample),
            depth_window_px=depth_window,
            depth_scaling=DepthScaling(depth_scaling),
            reference=reference,
            ours_options=ours_options,
        )
        return config if method is None else config.with_method(method)
    except ConfigurationError as exc:
        raise click.BadParameter(str(exc), param_hint="--method") from None


_DEPTHMAP_OPTIONS = (
    click.option(
        "--depth-sample",
        type=Choice([s.value for s in DepthSample]),
        default=DepthSample.CENTRE.value,
        show_default=True,
        help="depthmap: box centre pixel, a window around it, or the box's lower part.",
    ),
    click.option(
        "--depth-window",
        type=int,
        default=5,
        show_default=True,
        help="depthmap: window side in pixels (odd) for --depth-sample window.",
    ),
    click.option(
        "--depth-scaling",
        type=Choice([s.value for s in DepthScaling]),
        default=DepthScaling.NONE.value,
        show_default=True,
        help="depthmap: per-frame median scaling for scale-less depth (contact = "
        "flat-ground distances, truth = ground truth; docs/evaluation.md).",
    ),
)


def estimator_options(
    depth: bool = False,
) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """The options of every estimator (``--alphas``, ``--thresholds``; with ``depth`` also
    the ``--depth-sample/-window/-scaling`` of ``depthmap``), handed to the command as one
    ``estimator_config`` (:class:`~slopedist.estimators.EstimatorConfig`; the command sets its
    method with :meth:`~slopedist.estimators.EstimatorConfig.with_method`)."""

    def decorate(command: Callable[..., Any]) -> Callable[..., Any]:
        @functools.wraps(command)
        def wrapper(
            *args: Any,
            alphas: str,
            thresholds: str,
            reference: str | None,
            ours_options: tuple[str, ...],
            **kwargs: Any,
        ) -> Any:
            depth_values = {
                k: kwargs.pop(k)
                for k in ("depth_sample", "depth_window", "depth_scaling")
                if k in kwargs
            }
            kwargs["estimator_config"] = estimator_config(
                alphas,
                thresholds,
                **depth_values,
                reference=reference,
                ours_options=parse_ours_options(ours_options),
            )
            return command(*args, **kwargs)

        options = (alphas_option, thresholds_option, reference_option, ours_option) + (
            _DEPTHMAP_OPTIONS if depth else ()
        )
        return apply_options(options, wrapper)

    return decorate
