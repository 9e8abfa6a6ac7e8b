"""The accuracy tables of pooled scores (:class:`~slopedist.evaluation.metrics.PooledScores`), built
once for ``slopedist eval`` (printed as text), ``slopedist demo`` (text and CSV) and
``slopedist report`` (Markdown, HTML and CSV).

Distances and errors in metres; AbsRel, SqRel, RMSElog and the δ accuracies without unit;
times in milliseconds per frame.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from slopedist.evaluation.metrics import (
    DISTANCE_BINS_M,
    GAUSSIAN_COVERAGE,
    SIGMA_LEVELS,
    PooledScores,
    bin_label,
    compact_names,
)
from slopedist.evaluation.table import Table, best_marks, format_texts

RMSE_TITLE = "Table 1: RMSE (m) per sequence and method"

METRIC_COLUMNS: tuple[tuple[str, str, bool | None], ...] = (
    ("n", "n", None),
    ("rmse", "RMSE", False),
    ("mae", "MAE", False),
    ("abs_rel", "AbsRel", False),
    ("sq_rel", "SqRel", False),
    ("rmse_log", "RMSElog", False),
    ("delta_1.25", "δ<1.25", True),
    ("delta_1.25^2", "δ<1.25²", True),
    ("delta_1.25^3", "δ<1.25³", True),
)
"""Summary key, column header, and whether larger is better (None: not compared)."""
RECALL_COLUMN = ("recall", "recall", True)
TIME_COLUMN = ("ms_per_frame", "ms/frame", None)


def _max_n(summaries: Mapping[str, Mapping[str, Any]], methods: list[str]) -> int:
    """The largest number of scored targets of the methods (0 when none)."""
    return max((int(summaries[m]["n"]) for m in methods), default=0)


def same_targets(summaries: Mapping[str, Mapping[str, Any]], methods: list[str]) -> bool:
    """Whether the methods that have a result in ``summaries`` were scored against the same
    number of true targets (``n_gt``) and scored as many (``n``): runs over other frames or
    other boxes of a sequence score other targets, and a method that leaves some out (an upper
    bound, a withheld distance) is scored over fewer; their errors are not compared."""
    ran = [summaries[m] for m in methods if not summaries[m].get("missing")]
    return len({(r.get("n_gt"), r.get("n")) for r in ran}) <= 1


def _missing_notes(scores: PooledScores) -> list[str]:
    notes = []
    for m in scores.methods:
        miss = {
            s: scores.summaries[s][m]["missing"]
            for s in scores.sequences
            if scores.summaries[s][m].get("missing")
        }
        if miss:
            notes.append(
                f"{m}: no result on {', '.join(miss)} ({next(iter(miss.values()))}); "
                f"its overall pools {compact_names(scores.pooled[m]) or 'nothing'}."
            )
    return notes


def rmse_table(
    scores: PooledScores,
    title: str = RMSE_TITLE,
    row_label: str = "sequence",
    key: str = "table1_rmse",
) -> Table:
    """RMSE (m) per sequence × method, then the ``overall`` row (each method pooled over its
    own sequences) and, when those differ, the ``common`` row; best per row in bold (not on
    an ``overall`` row pooled over different sequences, nor on a row whose methods were scored
    over different targets: :func:`same_targets`; a note says so). ``n`` = most targets
    scored (each method's where they differ, in the note)."""
    methods = scores.methods
    rows: list[list[Any]] = []
    bold: list[list[bool]] = []
    apart: list[str] = []

    def add(label: str, summaries: Mapping[str, Mapping[str, Any]], compare: bool) -> None:
        vals = [float(summaries[m]["rmse"]) for m in methods]
        rows.append([label, _max_n(summaries, methods), *vals])
        if compare and not same_targets(summaries, methods):
            compare = False
            counts = ", ".join(
                f"{m} {int(summaries[m]['n'])}" for m in methods if not summaries[m].get("missing")
            )
            apart.append(f"{label} (n: {counts})")
        bold.append([False, False, *(best_marks(vals) if compare else [False] * len(vals))])

    for s in scores.sequences:
        add(s, scores.summaries[s], True)
    add("overall", scores.overall, scores.common is None)
    notes = _missing_notes(scores)
    if scores.common is not None:
        add("common", scores.common["methods"], True)
        notes.append(
            "common: every method pooled over the sequences all of them ran on ("
            + (compact_names(scores.common["sequences"]) or "none")
            + ")."
        )
    else:
        notes.append("overall: pooled over all targets of " + compact_names(scores.sequences) + ".")
    if apart:
        notes.append(
            f"{', '.join(apart)}: the methods were scored over different targets (runs over "
            "other frames or boxes, or an upper bound or a withheld distance not scored): "
            "not compared."
        )
    headers = [row_label, "n", *methods]
    return Table(key, title, headers, rows, bold, "\n".join(notes), {1: "d"})


def metrics_table(
    scores: PooledScores,
    scope: Mapping[str, Mapping[str, Any]],
    title: str,
    key: str,
    compare: bool = True,
    with_time: bool = False,
) -> Table:
    """The extended metrics of ``scope`` (``{method: summary}``) per method, with the recall
    when the summaries have one and the time per frame when ``with_time``; best in bold when
    ``compare`` (the methods ran on the same sequences) and :func:`same_targets`."""
    columns = list(METRIC_COLUMNS)
    if scores.methods and "recall" in scope[scores.methods[0]]:
        columns.append(RECALL_COLUMN)
    if with_time:
        columns.append(TIME_COLUMN)
    rows = [
        [m, *(int(scope[m][k]) if k == "n" else float(scope[m][k]) for k, _, _ in columns)]
        for m in scores.methods
    ]
    bold = [[False] * (len(columns) + 1) for _ in rows]
    compare = compare and same_targets(scope, scores.methods)
    for j, (_, _, larger) in enumerate(columns, start=1):
        if larger is None or not compare:
            continue
        for i, b in enumerate(best_marks([r[j] for r in rows], larger)):
            bold[i][j] = b
    formats = {1: "d"}
    formats.update({j: ".3f" for j, (k, _, _) in enumerate(columns, start=1) if k not in ("n",)})
    formats.update(
        {j: ".2f" for j, (k, _, _) in enumerate(columns, start=1) if k in ("rmse", "mae")}
    )
    headers = ["method", *(label for _, label, _ in columns)]
    return Table(key, title, headers, rows, bold, formats=formats)


def bins_table(scores: PooledScores, scope: Mapping[str, Mapping[str, Any]], note: str) -> Table:
    """RMSE, AbsRel and δ<1.25 per ground-truth distance bin and method; best per bin in bold
    (when the methods were scored against the same targets, :func:`same_targets`)."""
    rows: list[list[Any]] = []
    bold: list[list[bool]] = []
    compare = same_targets(scope, scores.methods)
    for lo, hi in DISTANCE_BINS_M:
        label = bin_label(lo, hi)
        block = [
            [
                label,
                m,
                int(scope[m]["bins"][label]["n"]),
                float(scope[m]["bins"][label]["rmse"]),
                float(scope[m]["bins"][label]["abs_rel"]),
                float(scope[m]["bins"][label]["delta_1.25"]),
            ]
            for m in scores.methods
        ]
        marks = [[False] * 6 for _ in block]
        for j, larger in ((3, False), (4, False), (5, True)):
            for i, b in enumerate(best_marks([r[j] for r in block], larger)):
                marks[i][j] = b and compare
        rows += block
        bold += marks
    return Table(
        "metrics_by_distance",
        "Metrics per ground-truth distance bin (m)",
        ["bin (m)", "method", "n", "RMSE", "AbsRel", "δ<1.25"],
        rows,
        bold,
        note,
        {2: "d", 4: ".3f", 5: ".3f"},
    )


def uncertainty_table(scores: PooledScores, truth: str = "") -> Table | None:
    """How well each method's own 1σ (``sigma_m``) describes its errors, overall: the share
    of errors within 1, 2 and 3 σ against a Gaussian's, and the RMS of error/σ; for the
    methods that report a σ (None when none does). ``truth``: what the errors are taken
    against, named in the title (empty: not named)."""
    methods = [m for m in scores.methods if "uncertainty" in scores.overall[m]]
    if not methods:
        return None
    rows = []
    for m in methods:
        u = scores.overall[m]["uncertainty"]
        rows.append(
            [
                m,
                int(u["n_sigma"]),
                *(float(u[f"within_{k}sigma"]) for k in SIGMA_LEVELS),
                float(u["z_rms"]),
            ]
        )
    headers = [
        "method",
        "n",
        *(f"within {k}σ ({GAUSSIAN_COVERAGE[k]:.3f})" for k in SIGMA_LEVELS),
        "RMS error/σ (1)",
    ]
    note = (
        "Each method's own σ (records column sigma_m, of its own reference point) against "
        "its errors, pooled as the overall row; in brackets what a right Gaussian σ gives. "
        "Fewer errors within kσ (or RMS error/σ above 1) means the σ promises more than the "
        "estimates keep."
    )
    formats = {1: "d", **{j: ".3f" for j in range(2, 3 + len(SIGMA_LEVELS))}}
    return Table(
        "uncertainty",
        "Uncertainty: errors" + (f" against {truth}" if truth else "") + " within the "
        "methods' own σ",
        headers,
        rows,
        note=note,
        formats=formats,
    )


def score_tables(scores: PooledScores, with_time: bool = False) -> list[Table]:
    """Table 1 (RMSE per sequence), the extended metrics and the per-bin metrics: on the
    common sequences when the methods ran on different ones, else overall; then the
    :func:`uncertainty_table` when a method reports its σ."""
    tables = [rmse_table(scores)]
    if scores.common is not None:
        common = scores.common["methods"]
        names = compact_names(scores.common["sequences"])
        tables.append(
            metrics_table(
                scores,
                common,
                f"Extended metrics, every method on the common sequences ({names})",
                "metrics_common",
                with_time=with_time,
            )
        )
        tables.append(bins_table(scores, common, "Pooled over the common sequences."))
    tables.append(
        metrics_table(
            scores,
            scores.overall,
            "Extended metrics, overall (each method pooled over the sequences it ran on)",
            "metrics_overall",
            compare=scores.common is None,
            with_time=with_time,
        )
    )
    if scores.common is None:
        tables.append(bins_table(scores, scores.overall, "Pooled over all sequences."))
    sigma = uncertainty_table(scores)
    return tables if sigma is None else [*tables, sigma]


def format_report_tables(report: Mapping[str, Any]) -> str:
    """The :func:`score_tables` of a JSON evaluation report (``slopedist eval``), as text, and
    how the truth's reference point and the learned peer were handled when the protocol says."""
    text = format_texts(score_tables(PooledScores.from_report(report), with_time=True))
    protocol = report.get("protocol", {})
    truth = protocol.get("ground_truth", {})
    if "methods_compared_at" in truth:
        text += (
            f"\nTruth refers to the vehicle's {truth['reference']}; methods compared at "
            f"{truth['methods_compared_at']}."
        )
    if protocol.get("learned_peer"):
        text += f"\nlearned-peer: {protocol['learned_peer']}."
    return text
