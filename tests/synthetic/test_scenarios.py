"""Scenario files: the built-in suite loads; mistakes are reported with file, line and field."""

from __future__ import annotations

from pathlib import Path

import pytest

from slopedist.core.errors import InputFileError, MissingInputError
from slopedist.synthetic.scenarios import (
    SUITE,
    builtin_names,
    builtin_text,
    load_scenario,
)
from slopedist.synthetic.scene import simulate_truth

MINIMAL = """
name = "mine"
[ego]
speed_kmh = 36.0
[[target]]
start_m = 20.0
speed_kmh = 40.0
"""


def _write(tmp_path: Path, text: str, name: str = "s.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_the_suite_is_built_in_and_loads() -> None:
    assert builtin_names()[: len(SUITE)] == list(SUITE)
    for name in SUITE:
        sc = load_scenario(name)
        assert sc.name == name and sc.description.strip()
        assert 100 <= sc.n_frames <= 150, "demo scenarios are 10-15 s at 10 Hz"
        truth = simulate_truth(sc)
        # the first target is in view in most frames (the scenario shows something)
        assert truth.in_view[:, 0].mean() > 0.9


def test_minimal_file_and_defaults(tmp_path: Path) -> None:
    sc = load_scenario(_write(tmp_path, MINIMAL))
    assert sc.name == "mine" and sc.n_frames == 120
    assert sc.ego.speed_mps == pytest.approx(10.0)
    assert sc.targets[0].track_id == 1 and sc.targets[0].lateral_m == pytest.approx(-1.75)
    assert sc.camera.f == pytest.approx(721.5377) and sc.camera.rig.height_m == 1.65
    assert sc.source == str(tmp_path / "s.toml")


def test_a_scenario_without_targets_is_an_empty_road(tmp_path: Path) -> None:
    path = _write(tmp_path, "duration_s = 0.5\n[ego]\nspeed_kmh = 30.0\n")
    sc = load_scenario(path)
    assert sc.targets == () and sc.n_frames == 5
    truth = simulate_truth(sc)
    assert truth.z_m.shape == (5, 0) and truth.in_view.shape == (5, 0)


def test_builtin_text_round_trips_through_a_user_file(tmp_path: Path) -> None:
    text = builtin_text("target_steep_uphill")
    a = load_scenario("target_steep_uphill")
    b = load_scenario(_write(tmp_path, text, "copy.toml"))
    assert a.road == b.road and a.targets == b.targets and a.seed == b.seed


@pytest.mark.parametrize(
    "text,field,line,words",
    [
        (
            MINIMAL + "[[road.curve]]\nstart_m = 1.0\nlength_m = 5.0\nradius = 100.0\n",
            "road.curve[0].radius",
            11,
            "unknown field",
        ),
        (
            MINIMAL.replace("speed_kmh = 40.0", 'speed_kmh = "fast"'),
            "target[0].speed_kmh",
            7,
            "must be a number",
        ),
        (MINIMAL.replace("start_m = 20.0\n", ""), "target[0].start_m", 5, "required"),
        (MINIMAL.replace("[ego]\nspeed_kmh = 36.0\n", ""), "ego", None, "required table"),
        (
            MINIMAL + "[[target]]\nstart_m = 40.0\nspeed_kmh = 30.0\nlane = 4\n",
            "target[1].lane",
            11,
            "a lane of the road",
        ),
        (
            MINIMAL + "[[target]]\nid = 1\nstart_m = 40.0\nspeed_kmh = 30.0\n",
            "target[1].id",
            9,
            "used twice",
        ),
        (
            MINIMAL.replace("speed_kmh = 40.0", "speed_kmh = 40.0\nwheelbase_m = 5.0"),
            "target[0]",
            5,
            "wheelbase_m",
        ),
        *(  # a vehicle that vanished from the truth and the boxes (a numpy warning only)
            (
                MINIMAL.replace("speed_kmh = 40.0", f"speed_kmh = 40.0\n{name} = {value}"),
                f"target[0].{name}",
                8,
                "m, got",
            )
            for name, value in (
                ("wheelbase_m", "1e-300"),
                ("length_m", "1e-300"),
                ("width_m", "0.001"),
                ("height_m", "1e4"),
            )
        ),
        (MINIMAL + "[road]\nstart_grade_pct = 55\n", "road.start_grade_pct", 9, "±40"),
        (MINIMAL + "[noise]\ntruncate = 1\n", "noise.truncate", 9, "true or false"),
        (
            MINIMAL + "[camera]\npitch_noise_band_hz = [1.0]\n",
            "camera.pitch_noise_band_hz",
            9,
            "list of 2",
        ),
        (MINIMAL.replace('name = "mine"', 'name = "my hill"'), "name", 2, "letters, digits"),
        (
            MINIMAL.replace("start_m = 20.0", "start_m = 2.0"),
            "target[0].start_m",
            6,
            "overlaps the ego at t = 0 s",
        ),
        (
            MINIMAL + "[[target]]\nstart_m = 40.0\nspeed_kmh = 10.0\n",
            "target[1].start_m",
            9,
            "overlaps target[0] at t = 1.9 s",
        ),
        (MINIMAL + "[camera]\nfocal_px = 5\n", "camera.focal_px", 9, "50..20000 px"),
        (MINIMAL + "[camera]\nfocal_px = 1e5\n", "camera.focal_px", 9, "50..20000 px"),
        (MINIMAL + "[camera]\ncx_px = -3.0\n", "camera.cx_px", 9, "inside the image"),
        (
            MINIMAL + "[camera]\nimage_height = 48\ncy_px = 300.0\n",
            "camera.cy_px",
            10,
            "inside the image",
        ),
        (MINIMAL + "[camera]\nheight_m = 80.0\n", "camera.height_m", 9, "(0, 50] m"),
    ],
)
def test_mistakes_name_file_line_and_field(
    tmp_path: Path, text: str, field: str, line: int | None, words: str
) -> None:
    path = _write(tmp_path, text)
    with pytest.raises(InputFileError) as info:
        load_scenario(path)
    err = info.value
    assert err.field == field
    assert err.line == line
    assert words in str(err) and str(path) in str(err)


def test_toml_syntax_error_names_the_line(tmp_path: Path) -> None:
    path = _write(tmp_path, MINIMAL + "[road\nlanes = 2\n")
    with pytest.raises(InputFileError, match="not valid TOML") as info:
        load_scenario(path)
    assert info.value.line == 8


def test_unknown_name_and_missing_file() -> None:
    with pytest.raises(MissingInputError, match="built-in: same_flat"):
        load_scenario("no_such_scenario")
    with pytest.raises(MissingInputError, match="not found"):
        load_scenario("missing/dir/s.toml")


@pytest.mark.parametrize("value", ["1e308", "-1e308", "2e6"])
def test_huge_numbers_are_clear_errors(tmp_path: Path, value: str) -> None:
    text = builtin_text("bumps_and_curves").replace("start_m = 20.0", f"start_m = {value}", 1)
    path = tmp_path / "evil.toml"
    path.write_text(text)
    line = text.splitlines().index(f"start_m = {value}") + 1
    with pytest.raises(
        InputFileError,
        match=rf"line {line}, field 'target\[0\]\.start_m': must be finite and within",
    ):
        load_scenario(path)


def test_non_utf8_huge_integer_and_oversized_scenario_files(tmp_path: Path) -> None:
    path = tmp_path / "latin1.toml"
    path.write_bytes(b'name = "x"\ndescription = "caf\xe9"\n')
    with pytest.raises(InputFileError, match=r"line 2: not UTF-8 text"):
        load_scenario(path)
    path.write_bytes(b"seed = " + b"9" * 200_000 + b"\n")
    with pytest.raises(InputFileError, match=r"not valid TOML"):
        load_scenario(path)
    big = tmp_path / "big.toml"
    big.write_bytes(b"# " + b"x" * 1_000_000 + b"\n")
    with pytest.raises(InputFileError, match="larger than"):
        load_scenario(big)
