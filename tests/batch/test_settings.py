"""The run settings of a batch drive: the ``ours_options`` cell parser (hypothesis), the cells
written back in ``fleet/settings.csv`` read again as the same settings, the batch-wide values."""

from __future__ import annotations

from dataclasses import fields

from hypothesis import given
from hypothesis import strategies as st

from slopedist.batch.settings import (
    CELL_PARSERS,
    LIST_SEPARATOR,
    RunSettings,
    settings_cell,
    settings_json,
    unapplied,
)
from slopedist.core.errors import ConfigurationError
from slopedist.estimators.ours.config import OursAblation, OursConfig, settable_options

BOOL_OPTIONS = sorted(
    f.name for f in (*fields(OursConfig), *fields(OursAblation)) if str(f.type) == "bool"
)
POSITIVE_OPTIONS = ["box_sigma_px", "gate_sigma", "max_age_s", "yaw_memory_s", "truncation_factor"]
"""Float options whose only rule is > 0 (OursConfig's and OursAblation's checks)."""

parse_cell = CELL_PARSERS["ours_options"]


@st.composite
def option_cells(draw: st.DrawFn) -> tuple[str, dict[str, bool | float]]:
    """A valid ``ours_options`` cell (random order, spaces and empty items) and its options."""
    values: dict[str, bool | float] = draw(
        st.dictionaries(st.sampled_from(BOOL_OPTIONS), st.booleans(), max_size=4)
    )
    values |= draw(
        st.dictionaries(
            st.sampled_from(POSITIVE_OPTIONS),
            st.floats(min_value=1e-3, max_value=1e3, allow_nan=False),
            max_size=3,
        )
    )
    spellings = {True: ["true", "Yes", "on", "1"], False: ["false", "NO", "off", "0"]}
    items = []
    for key, value in values.items():
        text = draw(st.sampled_from(spellings[value])) if isinstance(value, bool) else repr(value)
        items.append(f"{draw(st.sampled_from(['', ' ']))}{key}={text}")
    items = draw(st.permutations(items)) + draw(st.lists(st.just(" "), max_size=2))
    return LIST_SEPARATOR.join(items), values


@given(option_cells())
def test_an_ours_options_cell_gives_its_options(cell: tuple[str, dict[str, bool | float]]) -> None:
    text, values = cell
    parsed = RunSettings(ours_options=parse_cell(text)).ours_options
    assert parsed == tuple(sorted(values.items()))
    written = settings_cell(settings_json({"ours_options": parsed})["ours_options"])
    assert RunSettings(ours_options=parse_cell(written)).ours_options == parsed  # round trip


@given(
    st.one_of(
        st.text(alphabet=st.sampled_from("abdeiotw_=;,.0123456789 -"), max_size=40),
        st.text(max_size=30),
    )
)
def test_an_ours_options_cell_is_options_or_a_configuration_error(text: str) -> None:
    try:
        pairs = parse_cell(text)
    except ConfigurationError:
        return
    assert "," not in text
    assert all(key in settable_options() for key, _ in pairs)
    assert len({key for key, _ in pairs}) == len(pairs)


def test_settings_cells_read_back_as_the_same_settings() -> None:
    settings = RunSettings(
        "nearest_face",
        (("size_evidence_time_s", None), ("use_width", False), ("gate_sigma", 4.5)),
        ("Car", "Van"),
        offline=True,
        overlay=True,
        columns="all",
        overlay_format="png",
        export=("tum", "mcap"),
        generic_classes=("car",),
    )
    cells = {k: settings_cell(v) for k, v in settings_json(settings.__dict__).items()}
    assert cells["ours_options"] == "gate_sigma=4.5;size_evidence_time_s=none;use_width=false"
    assert (cells["export"], cells["vehicle_classes"]) == ("mcap;tum", "Car;Van")
    text = {k: v if isinstance(v, str) else str(v).lower() for k, v in cells.items()}
    assert RunSettings(**{k: CELL_PARSERS[k](v) for k, v in text.items()}) == settings
    assert settings.changed().keys() == set(cells)
    assert RunSettings().changed() == {}


def test_batch_wide_values_no_drive_takes_are_warned_about() -> None:
    batch = RunSettings(reference="contact", ours_options=(("use_width", False),), offline=True)
    assert unapplied(batch, ["ours", "paper"]) == []
    assert unapplied(batch, ["ours-selfcal"]) == [
        "--offline applies to no drive of this batch (methods: ours-selfcal)"
    ]
    warnings = unapplied(batch, ["paper", "flat", "paper"])
    # --reference applies to every method: no warning
    assert [w.split()[0] for w in warnings] == ["--ours-option", "--offline"]
    assert all(w.endswith("(methods: flat, paper)") for w in warnings)
    assert unapplied(RunSettings(), ["paper"]) == []
    generic = RunSettings(generic_classes=("car",))
    assert unapplied(generic, ["ours-offline"]) == []
    assert unapplied(generic, ["paper"])[0].startswith("--generic-class applies to no drive")
