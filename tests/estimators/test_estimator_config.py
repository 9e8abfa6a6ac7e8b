"""One place that turns options into a configured estimator: which option reaches which method."""

from __future__ import annotations

import dataclasses
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from slopedist.core.camera import Camera
from slopedist.core.errors import ConfigurationError
from slopedist.estimators import (
    DepthMapEstimator,
    EstimatorConfig,
    ImuEgoEstimator,
    ImuEstimator,
    PaperEstimator,
    available_methods,
    build_estimator,
    make_estimator,
)
from slopedist.estimators.depthmap import DepthSample, DepthScaling
from slopedist.estimators.ours.config import (
    OursConfig,
    configs_of,
    experimental_options,
    parse_option,
    settable_options,
    user_options,
)
from slopedist.estimators.ours.estimator import OursEstimator

CAMERA = Camera(721.5, 609.6, 172.9, 1.65)
STEEP = EstimatorConfig(alphas_deg=(20.0, 30.0, 40.0), thresholds_px=(5.0, -5.0, -15.0))


@pytest.mark.parametrize("method", ["paper", "imu"])
def test_eq7_options_reach_every_method_built_on_paper(method: str) -> None:
    est = build_estimator(STEEP.with_method(method), CAMERA)
    assert isinstance(est, PaperEstimator)
    assert est.adjustment.alphas_rad == pytest.approx(tuple(map(math.radians, (20, 30, 40))))
    assert est.adjustment.thresholds_px == (5.0, -5.0, -15.0)


def test_options_a_method_does_not_have_are_ignored() -> None:
    assert STEEP.options("imu-ego") == {} and STEEP.options("flat") == {}
    assert isinstance(build_estimator(STEEP.with_method("imu-ego"), CAMERA), ImuEgoEstimator)
    assert not isinstance(build_estimator(STEEP.with_method("imu-ego"), CAMERA), ImuEstimator)


def test_depth_options_reach_depthmap() -> None:
    cfg = EstimatorConfig(
        "depthmap", depth_sample="window", depth_window_px=7, depth_scaling="contact"
    )
    est = build_estimator(cfg, CAMERA)
    assert isinstance(est, DepthMapEstimator)
    assert est.sample is DepthSample.WINDOW and est.window_px == 7
    assert est.scaling is DepthScaling.CONTACT


def test_method_options_feed_an_evaluation_config() -> None:
    options = STEEP.method_options(available_methods())
    assert set(options) == set(available_methods())
    assert set(options["paper"]) == set(options["imu"]) == {"adjustment"}
    assert options["ours"] == {}


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"method": "nope"}, "unknown method 'nope'"),
        ({"thresholds_px": (0.0, 0.0, -20.0)}, "must decrease"),
        ({"depth_sample": "middle"}, "middle"),
    ],
)
def test_bad_options_are_configuration_errors(kwargs: dict, message: str) -> None:
    with pytest.raises(ConfigurationError, match=message):
        EstimatorConfig(**kwargs)


def test_ours_options_reach_ours_and_ours_selfcal() -> None:
    """``ours_options`` (``--ours-option``) set the ``ours`` configuration, with the reference
    point; other methods ignore them."""
    cfg = EstimatorConfig(
        "ours", reference="contact", ours_options=(("odd_object_weight", 0.0), ("use_width", False))
    )
    for method in ("ours", "ours-selfcal"):
        est = build_estimator(cfg.with_method(method), CAMERA)
        assert isinstance(est, OursEstimator)
        assert est.ablation.odd_object_weight == 0.0 and not est.ablation.use_width
        assert est.config.reference == "contact"
    assert cfg.options("paper").keys() == {"adjustment"} and cfg.options("flat") == {}


def test_generic_classes_reach_the_methods_built_on_ours() -> None:
    """``generic_classes`` (``--generic-class``) become option ``generic_classes`` of ``ours``,
    ``ours-selfcal`` and ``ours-offline``; other methods ignore them; a bare text is refused."""
    cfg = EstimatorConfig("ours", generic_classes=("car",))
    for method in ("ours", "ours-selfcal", "ours-offline"):
        est = build_estimator(cfg.with_method(method), CAMERA)
        assert isinstance(est, OursEstimator) and est.config.generic_classes == ("car",)
    assert "generic_classes" not in cfg.options("paper") and cfg.options("flat") == {}
    with pytest.raises(ConfigurationError, match="collection of class names"):
        EstimatorConfig("ours", generic_classes="car")  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("odd_object_weight=0", ("odd_object_weight", 0.0)),
        (" size_learning = Yes ", ("size_learning", True)),
        ("use_width=0", ("use_width", False)),
        ("size_evidence_time_s=none", ("size_evidence_time_s", None)),
        ("box_sigma_px=1e-1", ("box_sigma_px", 0.1)),
    ],
)
def test_parse_ours_option(text: str, expected: tuple) -> None:
    assert parse_option(text) == expected


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("bogus=1", "choose from .*odd_object_weight"),
        ("priors=x", "not an ours option settable here"),
        ("generic_classes=car", "use --generic-class NAME"),
        ("reference=contact", "use --reference"),
        ("box_sigma_px=inf", "'inf' is not a float"),
        ("min_iou=1.5", r"min_iou must be in \[0, 1\]"),
        ("=3", "is not KEY=VALUE"),
    ],
)
def test_bad_ours_options_are_configuration_errors(text: str, message: str) -> None:
    with pytest.raises(ConfigurationError, match=message):
        parse_option(text)


@given(st.text(max_size=40))
def test_parse_ours_option_gives_a_value_or_a_configuration_error(text: str) -> None:
    try:
        key, _ = parse_option(text)
    except ConfigurationError:
        return
    assert key in settable_options()


@pytest.mark.parametrize("method", ["flat", "ego", "paper", "imu", "imu-ego", "depthmap", "ours"])
def test_an_option_a_method_does_not_take_is_a_configuration_error(method: str) -> None:
    """Not a bare TypeError from the constructor: the message names the method and lists
    what it takes."""
    with pytest.raises(ConfigurationError, match=rf"unknown option\(s\) for method '{method}'"):
        make_estimator(method, Camera(721.5, 609.6, 172.9), bogus=1)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"box_sigma_px": "1"}, "box_sigma_px must be a finite number > 0, got '1'"),
        ({"box_sigma_px": True}, "box_sigma_px must be a finite number > 0, got True"),
        ({"min_iou": "0.3"}, "min_iou must be in \\[0, 1\\], got '0.3'"),
        ({"atypical_height_factor": 0.0}, "atypical_height_factor must be a finite number"),
        ({"atypical_height_factor": -1.0}, "atypical_height_factor must be a finite number"),
        ({"atypical_height_weight": "0.1"}, "atypical_height_weight and odd_object_weight"),
        ({"yaw_evidence_weight": 2.0}, "yaw_evidence_weight must be in \\(0, 1\\], got 2.0"),
        ({"motion_model": "no"}, "motion_model must be true or false, got 'no'"),
        ({"use_width": 0}, "use_width must be true or false, got 0"),
        ({"reference": "roof"}, "reference must be one of centre, nearest_face, contact"),
        ({"generic_classes": "Car"}, "generic_classes must be a collection.*'Car'"),
    ],
)
def test_ours_config_refuses_values_of_the_wrong_kind_or_range(kwargs: dict, message: str) -> None:
    """They were accepted (a text switch "no" is true, "Car" as generic classes became
    ("C", "a", "r"), a bool sigma 1 px, a factor 0 a zero height spread; an unknown reference
    only when an estimator was built) or failed with a bare TypeError (a text min_iou)."""
    with pytest.raises(ConfigurationError, match=message):
        configs_of(kwargs)
    with pytest.raises(ConfigurationError, match=message):
        make_estimator("ours", CAMERA, **kwargs)


def test_ten_options_and_the_experimental_rest() -> None:
    """At most ten options are a user's; the rest of what ``KEY=VALUE`` sets is the
    ablation's, experimental, and no key is both."""
    users = [f.name for f in dataclasses.fields(OursConfig)]
    assert len(users) <= 10 and {"reference", "generic_classes"} <= set(users)
    assert set(user_options()) <= set(users)
    assert "box_sigma_px" in users and "odd_object_weight" in experimental_options()
    assert not set(users) & set(experimental_options())
    assert sorted(user_options() + experimental_options()) == settable_options()


def test_ours_config_must_be_an_ours_config() -> None:
    """It failed with a bare AttributeError ('str' object has no attribute ...)."""
    with pytest.raises(ConfigurationError, match="ours option config must be an OursConfig"):
        make_estimator("ours", CAMERA, config="fast")


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"reference": "roof"}, "reference must be one of"),
        ({"ours_options": (("box_sigma_px", -1.0),)}, "box_sigma_px must be a finite number"),
        (
            {"ours_options": (("speed_of_light", 1.0),)},
            "unknown option\\(s\\) for method 'ours': speed_of",
        ),
        ({"ours_options": ("box_sigma_px",)}, "ours_options must be \\(name, value\\) pairs"),
        ({"thresholds_px": (0.0, -10.0)}, "thresholds_px must be three finite numbers"),
        ({"alphas_deg": (math.nan, 5.0, 6.0)}, "alphas_deg must be three finite numbers"),
    ],
)
def test_estimator_config_checks_its_options_when_made(kwargs: dict, message: str) -> None:
    """An unknown reference and bad ours options were accepted until an estimator was built
    from the config; two thresholds failed with a bare IndexError; a NaN step was accepted
    (NaN distances)."""
    with pytest.raises(ConfigurationError, match=message):
        EstimatorConfig(**kwargs)
