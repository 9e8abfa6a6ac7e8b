"""Option parsing helpers shared by the commands (degrees at the edge, lists, enums)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import click

from slopedist.camera import KITTI_CAMERA_HEIGHT_M
from slopedist.datasets.kitti_tracking import BoxSource, RotationSource
from slopedist.estimators import available_methods


def split_list(value: str | None) -> list[str] | None:
    """``"a,b , c"`` → ``["a", "b", "c"]``; None or empty → None."""
    if not value:
        return None
    return [v.strip() for v in value.split(",") if v.strip()]


def check_methods(names: list[str]) -> list[str]:
    """Fail with a usage error on an unknown method name."""
    known = available_methods()
    bad = [n for n in names if n not in known]
    if bad:
        raise click.BadParameter(
            f"unknown method(s) {', '.join(bad)}; choose from {', '.join(known)}",
            param_hint="--methods/--method",
        )
    return names


height_option = click.option(
    "--height",
    "height_m",
    type=float,
    default=KITTI_CAMERA_HEIGHT_M,
    show_default=True,
    help="Camera height above the road, metres.",
)
mount_option = click.option(
    "--mount-angle",
    "mount_angle_deg",
    type=float,
    default=0.0,
    show_default=True,
    help="Camera mount angle θ0 in the yz plane, degrees (paper eq. 2).",
)
lookback_option = click.option(
    "--lookback",
    "lookback_s",
    type=click.FloatRange(min=0.0, min_open=True),
    default=1.0,
    show_default=True,
    help="Look-back of the ego road gradient, seconds.",
)
alphas_option = click.option(
    "--alphas",
    default="3,5,6",
    show_default=True,
    help="Paper method: angle steps α1,α2,α3 in degrees (eq. 7).",
)
thresholds_option = click.option(
    "--thresholds",
    default="0,-10,-20",
    show_default=True,
    help="Paper method: Δy thresholds in pixels for α1,α2,α3 (eq. 7).",
)


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
    return nums[0], nums[1], nums[2]


def paper_options(alphas: str, thresholds: str) -> dict[str, object]:
    """Constructor options of the ``paper`` estimator from the command-line strings."""
    from slopedist.geometry import GradientAdjustment

    a = parse_triple(alphas, "--alphas")
    t = parse_triple(thresholds, "--thresholds")
    if not (t[0] > t[1] > t[2]):
        raise click.BadParameter(
            "thresholds must decrease (t1 > t2 > t3)", param_hint="--thresholds"
        )
    return {"adjustment": GradientAdjustment.from_degrees(a, t)}


def depthmap_options(func: Callable[..., Any]) -> Callable[..., Any]:
    """``--depth-sample``, ``--depth-window``, ``--depth-scaling``: how the ``depthmap`` method
    reads a depth map at a box (see :mod:`slopedist.estimators.depthmap`)."""
    from slopedist.estimators.depthmap import DepthSample, DepthScaling

    for option in reversed(
        (
            click.option(
                "--depth-sample",
                type=click.Choice([s.value for s in DepthSample]),
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
                type=click.Choice([s.value for s in DepthScaling]),
                default=DepthScaling.NONE.value,
                show_default=True,
                help="depthmap: per-frame median scaling for scale-less depth (contact = "
                "flat-ground distances, truth = ground truth; see the README).",
            ),
        )
    ):
        func = option(func)
    return func


def depthmap_estimator_options(sample: str, window_px: int, scaling: str) -> dict[str, object]:
    """Constructor options of the ``depthmap`` estimator from the command-line values."""
    return {"sample": sample, "window_px": window_px, "scaling": scaling}


def kitti_source_options(prefix: str = "") -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """``--rotation``, ``--boxes`` and ``--score`` of KITTI tracking sources (help text starts
    with ``prefix``)."""

    def decorate(command: Callable[..., Any]) -> Callable[..., Any]:
        for option in reversed(
            (
                click.option(
                    "--rotation",
                    type=click.Choice([r.value for r in RotationSource]),
                    default=RotationSource.ORBSLAM3.value,
                    show_default=True,
                    help=f"{prefix}Rotation source of the visual-odometry methods "
                    "(imu and imu-ego always use oxts).",
                ),
                click.option(
                    "--boxes",
                    type=click.Choice([b.value for b in BoxSource]),
                    default=BoxSource.GT.value,
                    show_default=True,
                    help=f"{prefix}Ground-truth boxes or PointRCNN detections.",
                ),
                click.option(
                    "--score",
                    type=float,
                    default=None,
                    help=f"{prefix}Keep detections with score >= SCORE (PointRCNN boxes).",
                ),
            )
        ):
            command = option(command)
        return command

    return decorate


def parse_size(value: str | None, what: str = "WIDTHxHEIGHT in pixels") -> tuple[int, int] | None:
    """``"1280x720"`` → ``(1280, 720)`` (positive integers); None or empty → None."""
    if not value:
        return None
    try:
        a, b = (int(v) for v in value.lower().split("x"))
    except ValueError:
        raise click.BadParameter(f"expected {what}, got '{value}'") from None
    if a <= 0 or b <= 0:
        raise click.BadParameter(f"expected {what} (positive), got '{value}'")
    return a, b
