"""The report of a run without ground truth: a per-track table, a small plot per leading
track on its own scale with the method's σ band, captions that claim no truth, and an HTML
page without Markdown syntax or repeated list items (also as headless Chromium renders it)."""

from __future__ import annotations

import math
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import pytest

from slopedist.evaluation.plots import new_figure
from slopedist.evaluation.report import ReportOptions, report_data, report_tables, write_report
from slopedist.evaluation.report.figures import draw_track_panel
from slopedist.evaluation.report.track_summary import leading_tracks, track_summaries
from tests.evaluation.report.test_report import CHROMIUM, chromium_command, write_run


def _row(frame: int, track: int, d: float, **extra: object) -> dict[str, object]:
    return {
        "frame": frame,
        "timestamp_s": 0.1 * frame,
        "track_id": track,
        "class": "Car",
        "method": "ours",
        "distance_m": d,
        "reference": "nearest_face",
        "status": "ok",
        "reason": "",
        **extra,
    }


def drive_rows() -> list[dict[str, object]]:
    """Track 2 closes in from 11 m to 6.5 m over 1 s (σ 0.5 m, TTC 5 s down to 2.3 s); track 7
    is cut by the image bottom for 0.6 s (upper bounds from 4 m); track 4 stays at 25 m;
    track 9 is seen in two frames at 30 m."""
    rows = [
        _row(k, 2, 11.0 - 0.5 * k, sigma_m=0.5, ttc_s=round(5.0 - 0.3 * k, 6)) for k in range(10)
    ]
    rows += [_row(k, 7, 4.0 + 0.1 * k, status="upper_bound", reason="cut_bottom") for k in range(6)]
    rows += [_row(k, 4, 25.0, sigma_m=2.0) for k in range(10)]
    rows += [_row(k, 9, 30.0) for k in (3, 4)]
    return rows


@pytest.fixture
def drive(tmp_path: Path) -> Path:
    folder = tmp_path / "drive"
    frames = [{"frame": k, "estimation_ms": 1.0} for k in range(10)]
    write_run(folder, drive_rows(), frames, extra=("sigma_m", "ttc_s"))
    return folder


def test_the_track_table_summarises_each_track_from_the_records(drive: Path) -> None:
    data = report_data(drive, ReportOptions())
    assert not data.has_truth and data.title == "Run report: drive"
    assert "Distances refer to the vehicle's nearest face (the gap)." in data.notes
    tables = report_tables(data)
    assert [t.key for t in tables] == ["tracks", "table2_time"]
    table = tables[0]
    assert table.headers == [
        "track",
        "first seen (s)",
        "last seen (s)",
        "frames estimated",
        "closest (m)",
        "1σ there (m)",
        "at (s)",
        "time < 10 m (s)",
        "least TTC (s)",
        "closest bound (m)",
    ]
    # ranked: longest closer than 10 m (track 2: 9.5 m and below from frame 3 on, 7 frames;
    # track 7's bounds, 6 frames), then the closest; track 9, seen twice, last
    assert [r[0] for r in table.rows] == [2, 7, 4, 9]
    two, seven = table.rows[0], table.rows[1]
    assert two[1:4] == [0.0, pytest.approx(0.9), 10]
    assert two[4:9] == [6.5, 0.5, pytest.approx(0.9), pytest.approx(0.7), pytest.approx(2.3)]
    assert math.isnan(two[9])
    assert seven[3] == 0 and math.isnan(seven[4]) and seven[9] == 4.0
    assert seven[7] == pytest.approx(0.6)
    assert "frame step (0.1 s)" in table.note


def test_a_lower_threshold_shortens_the_time_near(drive: Path) -> None:
    data = report_data(drive, ReportOptions(near_m=7.0))
    near = {s.track_id: s.near_s for s in track_summaries(data)}
    # track 2 below 7 m: 6.5 m only (frame 9); track 7's bounds (4.0..4.5 m) all
    assert near == {2: pytest.approx(0.1), 7: pytest.approx(0.6), 4: 0.0, 9: 0.0}
    assert report_tables(data)[0].headers[7] == "time < 7 m (s)"


def test_each_leading_track_gets_a_small_plot_without_a_truth_claim(
    drive: Path, tmp_path: Path
) -> None:
    data = report_data(drive, ReportOptions())
    assert leading_tracks(data, 6) == [("drive", 2), ("drive", 7), ("drive", 4)]
    written = write_report(data, tmp_path / "out", parquet=False)
    names = [f.name for f in written.figures]
    assert names == ["track_drive_2.png", "track_drive_7.png", "track_drive_4.png"]
    assert all(f.small and f.after == "tracks" for f in written.figures)
    for f in written.figures:
        assert "truth" not in f.caption
        assert (tmp_path / "out" / "figures" / f.name).read_bytes().startswith(b"\x89PNG")
    two, seven, _ = (f.caption for f in written.figures)
    assert two.startswith("Track 2: estimated distance to the vehicle's nearest face")
    assert "±1σ" in two and "upper bound" not in two
    assert "upper bound" in seven and "±1σ" not in seven


def test_a_track_plot_has_its_own_scale_and_its_legend_outside(drive: Path) -> None:
    data = report_data(drive, ReportOptions())
    fig = new_figure(5.6, 2.3)
    ax = fig.subplots()
    explained = draw_track_panel(ax, data, "drive", 2)
    # 6.5..11 m with a 0.5 m band: the axis ends a little over 11.5 m, not at 100 m
    assert ax.get_ylim() == pytest.approx((0.0, 1.15 * 11.5))
    assert [line.get_ydata()[0] for line in ax.get_lines()][-1] == 10.0  # the 10 m line
    assert explained[0].startswith("band: ±1σ") and explained[-1] == "dotted: 10 m"
    fig.canvas.draw()
    legend = ax.get_legend().get_window_extent()
    assert legend.x0 >= ax.get_window_extent().x1  # beside the data, not over it
    texts = [t.get_text() for t in ax.get_legend().get_texts()]
    assert texts == ["ours", "ours ±1σ"]


class _PageText(HTMLParser):
    """The text a reader sees (outside <script>, <style> and attributes) and the text of each
    <li>."""

    def __init__(self) -> None:
        super().__init__()
        self.text: list[str] = []
        self.items: list[str] = []
        self._hidden = 0
        self._item: list[str] | None = None

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self._hidden += tag in ("script", "style")
        if tag == "li":
            self._item = []

    def handle_endtag(self, tag: str) -> None:
        self._hidden -= tag in ("script", "style")
        if tag == "li" and self._item is not None:
            self.items.append("".join(self._item).strip())
            self._item = None

    def handle_data(self, data: str) -> None:
        if not self._hidden:
            self.text.append(data)
            if self._item is not None:
                self._item.append(data)


def page_problems(page: str) -> list[str]:
    """Markdown syntax a reader of the page would see (backticks, ``**``, ``![``) and list
    items said twice, or a list item that starts like another (two "Source:" lines)."""
    parser = _PageText()
    parser.feed(page)
    text = "".join(parser.text)
    problems = [f"literal {s!r} on the page" for s in ("`", "**", "![") if s in text]
    starts = [item.split(":")[0] for item in parser.items if ":" in item[:20]]
    problems += [
        f"repeated list item {i!r}" for i in set(parser.items) if parser.items.count(i) > 1
    ]
    problems += [f"two list items start {s!r}" for s in set(starts) if starts.count(s) > 1]
    return problems


def test_page_checker_sees_markdown_and_repeats() -> None:
    page = "<ul><li>Source: `a`</li><li>Source: b</li><li>x</li><li>x</li></ul><p>**b**</p>"
    assert sorted(page_problems(page)) == [
        "literal '**' on the page",
        "literal '`' on the page",
        "repeated list item 'x'",
        "two list items start 'Source'",
    ]
    assert page_problems("<ul><li><code>a</code> b</li></ul><script>`ok`</script>") == []


def test_the_page_has_no_markdown_syntax_and_no_repeated_items(drive: Path, tmp_path: Path) -> None:
    data = report_data(drive, ReportOptions())
    write_report(data, tmp_path / "out", parquet=False)
    page = (tmp_path / "out" / "report.html").read_text(encoding="utf-8")
    assert page_problems(page) == []
    assert "<title>Run report: drive</title>" in page
    assert "<code>slopedist run</code> output" in page  # the code span, as code
    # the track table, then its plots side by side, then Table 2
    tracks, grid, timing = (
        page.index(s) for s in ('id="tracks"', '<div class="small-figures">', "Table 2")
    )
    assert tracks < grid < timing
    assert page.count('<div class="small-figures">') == 1
    md = (tmp_path / "out" / "report.md").read_text(encoding="utf-8")
    assert "`slopedist run` output" in md and "figures/track_drive_2.png" in md


@pytest.mark.skipif(
    CHROMIUM is None,
    reason="headless Chromium not installed (Debian package 'chromium'; .ci/run installs it)",
)
def test_the_page_as_headless_chromium_renders_it(drive: Path, tmp_path: Path) -> None:
    data = report_data(drive, ReportOptions())
    write_report(data, tmp_path / "out", parquet=False)
    cmd = chromium_command(tmp_path / "profile", "--dump-dom", tmp_path / "out" / "report.html")
    dom = subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=False).stdout
    assert 'data-figures-total="3"' in dom and 'data-figures-loaded="3"' in dom, dom[:300]
    assert page_problems(dom) == []
