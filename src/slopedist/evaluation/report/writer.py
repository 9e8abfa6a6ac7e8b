"""Writing a report: ``report.md``, ``report.html`` (figures embedded as base64 PNG, no external
files), ``figures/*.png``, ``report.json`` (strict JSON) and one CSV per table plus the
per-target records (``records.csv``), every metric in long form (``metrics.csv``) and the ego
gradients (``theta.csv``), through :mod:`slopedist.io.formatting`; Parquet copies when pyarrow is
installed. Distances in metres, times in milliseconds per frame, angles in degrees."""

from __future__ import annotations

import base64
import html
import importlib.util
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from slopedist.core.paths import PATH_BYTES_ERRORS, utf8_text
from slopedist.evaluation.metrics import compact_names
from slopedist.evaluation.report.data import SOURCE_WORDS, ReportData
from slopedist.evaluation.report.figures import Figure, report_figures
from slopedist.evaluation.report.tables import METRIC_RECORD_FIELDS, metric_records, report_tables
from slopedist.evaluation.table import (
    Table,
    format_html,
    format_markdown,
    html_text,
    markdown_text,
    plain_text,
)
from slopedist.io.formatting import write_csv, write_json

HTML_SCRIPT = """<script>
window.addEventListener('load', function () {
  var imgs = document.querySelectorAll('img.figure');
  var ok = 0;
  imgs.forEach(function (im) { if (im.complete && im.naturalWidth > 0) { ok += 1; } });
  document.body.setAttribute('data-figures-total', String(imgs.length));
  document.body.setAttribute('data-figures-loaded', String(ok));
});
</script>"""
"""Sets ``data-figures-loaded`` / ``data-figures-total`` on ``<body>`` once the page has loaded:
the number of embedded figures that decoded (``naturalWidth > 0``), for automated checks."""

HTML_STYLE = """<style>
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1100px; color: #222; }
table { border-collapse: collapse; margin: 0.5em 0; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 0.2em 0.6em; text-align: right; }
th:first-child, td:first-child { text-align: left; }
thead { background: #f0f0f0; } .note { font-size: 0.85em; color: #555; max-width: 60em; }
figure { margin: 1em 0; } img.figure { max-width: 100%; border: 1px solid #ddd; }
figcaption { font-size: 0.9em; max-width: 60em; }
.small-figures { display: flex; flex-wrap: wrap; gap: 0 1.5em; }
.small-figures figure { flex: 0 1 520px; margin: 0.6em 0; }
code { font-size: 0.95em; background: #f4f4f4; padding: 0 0.2em; }
</style>"""


def parquet_available() -> bool:
    """Whether pyarrow (optional extra ``parquet``) is installed."""
    return importlib.util.find_spec("pyarrow") is not None


def write_table_files(
    path: Path, records: Sequence[Mapping[str, Any]], fields: Sequence[str], parquet: bool
) -> list[Path]:
    """Write ``records`` as CSV at ``path`` (and Parquet beside it when ``parquet``); returns
    the files."""
    written = [write_csv(path, records, fields)]
    if parquet:
        import pyarrow as pa
        import pyarrow.parquet as pq

        columns = {f: [utf8_text(r.get(f)) for r in records] for f in fields}
        with path.with_suffix(".parquet").open("wb") as fh:  # (a path of any bytes)
            pq.write_table(pa.table(columns), fh)
        written.append(path.with_suffix(".parquet"))
    return written


@dataclass
class WrittenReport:
    """What :func:`write_report` produced."""

    out_dir: Path
    tables: list[Table]
    figures: list[Figure]
    files: list[Path]


def _write_data_files(
    data: ReportData, tables: list[Table], out: Path, parquet: bool
) -> list[Path]:
    """One CSV per table, ``metrics.csv``, ``records.csv``, ``theta.csv`` and ``report.json``."""
    files: list[Path] = []
    for t in tables:
        files += write_table_files(out / f"{t.key}.csv", t.records(), t.headers, parquet)
    files += write_table_files(
        out / "metrics.csv", metric_records(data), METRIC_RECORD_FIELDS, parquet
    )
    files += write_table_files(
        out / "records.csv", data.records.records(), data.records.names, parquet
    )
    if len(data.theta):
        files += write_table_files(
            out / "theta.csv", data.theta.records(), data.theta.names, parquet
        )
    summary = {
        "title": data.title,
        "source": data.source,
        "kind": data.kind,
        "protocol": data.protocol,
        "methods": data.methods,
        "sequences": data.sequences,
        "sequence_summaries": data.summaries,
        "overall": data.overall,
        "pooled": data.pooled,
        "overall_common": data.common,
        "timing": data.timing,
        "notes": data.notes,
    }
    if data.fleet is not None:
        summary["fleet"] = vars(data.fleet)
    write_json(out / "report.json", summary, indent=1)
    return [*files, out / "report.json"]


def _intro(data: ReportData) -> list[str]:
    """The lines under the title: the source and what it holds, then the source's notes."""
    several = "s" if len(data.sequences) > 1 else ""
    return [
        f"Source: `{data.source}`, {SOURCE_WORDS[data.kind]}; "
        f"method{'s' if len(data.methods) > 1 else ''}: {', '.join(data.methods)}; "
        f"sequence{several}: {compact_names(data.sequences)}.",
        *data.notes,
    ]


def _page_order(tables: list[Table], figures: list[Figure]) -> list[Table | list[Figure]]:
    """The page's blocks in order: each table, followed by the figures that go after it
    (:attr:`Figure.after`), then the other figures; consecutive small figures as one
    block."""
    keys = {t.key for t in tables}
    blocks: list[Table | list[Figure]] = []
    for t in tables:
        blocks.append(t)
        blocks += _figure_blocks([f for f in figures if f.after == t.key])
    return blocks + _figure_blocks([f for f in figures if f.after not in keys])


def _figure_blocks(figures: list[Figure]) -> list[Table | list[Figure]]:
    """``figures`` as blocks: a run of small ones together, every other one alone."""
    blocks: list[Table | list[Figure]] = []
    for f in figures:
        last = blocks[-1] if blocks else None
        if f.small and isinstance(last, list) and last[-1].small:
            last.append(f)
        else:
            blocks.append([f])
    return blocks


def markdown_page(data: ReportData, tables: list[Table], figures: list[Figure]) -> str:
    """``report.md``: the notes, the tables, the figures (as files under ``figures/``)."""
    md = [f"# {_md(data.title)}", "", *[f"- {_md(n)}" for n in _intro(data)], ""]
    for block in _page_order(tables, figures):
        if isinstance(block, Table):
            md += [format_markdown(block), ""]
            continue
        for f in block:
            alt = _md(f.caption).replace("[", "\\[").replace("]", "\\]")
            md += [f"![{alt}](figures/{f.name})", "", f"*{_md(f.caption)}*", ""]
    return "\n".join(md)


def _md(text: str) -> str:
    """A line of the report's text in Markdown: outside its code spans (between backticks),
    names from the data cannot open an HTML tag
    (:func:`slopedist.evaluation.table.markdown_text`)."""
    parts = text.split("`")
    return "`".join(p if k % 2 else markdown_text(p) for k, p in enumerate(parts))


def _html_figure(f: Figure) -> str:
    b64 = base64.b64encode(f.png).decode("ascii")
    return (
        f'<figure><img class="figure" alt="{html.escape(plain_text(f.caption))}" '
        f'src="data:image/png;base64,{b64}"><figcaption>{html_text(f.caption)}'
        f"</figcaption></figure>"
    )


def html_page(data: ReportData, tables: list[Table], figures: list[Figure]) -> str:
    """``report.html``: one self-contained page (figures embedded as base64 PNG; the text's
    code spans as ``<code>``, no Markdown syntax)."""
    body = [
        f"<h1>{html.escape(data.title)}</h1>",
        "<ul>" + "".join(f"<li>{html_text(n)}</li>" for n in _intro(data)) + "</ul>",
    ]
    for block in _page_order(tables, figures):
        if isinstance(block, Table):
            body.append(format_html(block))
        elif block[0].small:
            body.append(
                '<div class="small-figures">' + "".join(map(_html_figure, block)) + "</div>"
            )
        else:
            body += [_html_figure(f) for f in block]
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        f"<title>{html.escape(data.title)}</title>{HTML_STYLE}</head>\n<body>\n"
        + "\n".join(body)
        + f"\n{HTML_SCRIPT}\n</body></html>\n"
    )


def write_report(
    data: ReportData,
    out_dir: str | Path,
    tracks: Sequence[tuple[str, int]] | None = None,
    n_tracks: int = 4,
    parquet: bool | None = None,
) -> WrittenReport:
    """Write ``report.md``, ``report.html``, figures, JSON, CSV (and Parquet) under ``out_dir``,
    each file as soon as it is ready.

    Raises:
        ConfigurationError: a chosen track has no records.
    """
    out = Path(out_dir)
    (out / "figures").mkdir(parents=True, exist_ok=True)
    use_parquet = parquet_available() if parquet is None else parquet
    tables = report_tables(data)
    files = _write_data_files(data, tables, out, use_parquet)
    figures = report_figures(data, tracks, n_tracks)
    for f in figures:
        (out / "figures" / f.name).write_bytes(f.png)
        files.append(out / "figures" / f.name)
    markdown, page = markdown_page(data, tables, figures), html_page(data, tables, figures)
    (out / "report.md").write_text(markdown, encoding="utf-8", errors=PATH_BYTES_ERRORS)
    (out / "report.html").write_text(page, encoding="utf-8", errors=PATH_BYTES_ERRORS)
    files += [out / "report.md", out / "report.html"]
    return WrittenReport(out, tables, figures, files)
