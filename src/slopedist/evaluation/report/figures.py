"""The report's figures: with a truth, distance against the truth over time for chosen tracks
and the error against the true distance; without one, a small plot of each leading track's
distance over time on its own scale, with the method's 1σ band; and the ego gradient θ over
time. Each method has its one colour of :func:`slopedist.evaluation.plots.method_colour`, as in
the demo's plots."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slopedist.core.errors import ConfigurationError
from slopedist.evaluation.metrics import AT_CAP_REASONS, compact_names
from slopedist.evaluation.plots import (
    BELOW_HORIZON_NOTE,
    DistanceSeries,
    draw_distance_panel,
    method_colour,
    new_figure,
    png_bytes,
)
from slopedist.evaluation.report.data import ReportData
from slopedist.evaluation.report.runs import reference_words
from slopedist.evaluation.report.track_summary import leading_tracks

ERROR_BIN_M = 5.0
"""Width of the ground-truth distance bins of the error-vs-distance figure, metres."""


LEADING_TRACK_PLOTS = 6
"""Tracks plotted one by one on the page of runs without truth (the leading ones)."""


@dataclass
class Figure:
    """A figure: file name, caption, PNG bytes; ``after``: the key of the table it follows on
    the page (None: after every table); ``small``: one of a set of small plots, laid out side
    by side."""

    name: str
    caption: str
    png: bytes
    after: str | None = None
    small: bool = False


def choose_tracks(data: ReportData, n: int) -> list[tuple[str, int]]:
    """The longest track (most records with a truth or an estimate, i.e. something to draw)
    of each of the ``n`` sequences whose longest tracks are longest; a track with neither (a
    run without truth whose every record is an upper bound or missing) is never chosen."""
    seq = np.asarray(data.records.data["sequence"], dtype=object)
    tid = data.records.array("track_id", int)
    drawn = np.isfinite(data.records.array("gt_distance_m")) | np.isfinite(
        data.records.array("distance_m")
    )
    best: dict[str, tuple[int, int]] = {}
    for s in data.sequences:
        sel = (seq == s) & (tid >= 0) & drawn
        if not sel.any():
            continue
        ids, counts = np.unique(tid[sel], return_counts=True)
        k = int(np.argmax(counts))
        best[s] = (int(counts[k]), int(ids[k]))
    ranked = sorted(best.items(), key=lambda kv: -kv[1][0])[:n]
    return [(s, t) for s, (_, t) in sorted(ranked)]


def track_series(
    data: ReportData, sequence: str, track: int
) -> tuple[NDArray[np.float64], DistanceSeries]:
    """The records of one track as a :class:`~slopedist.evaluation.plots.DistanceSeries` on the
    track's own
    time axis (seconds; NaN where a method has no estimate).

    Raises:
        ConfigurationError: the track has no records.
    """
    rec = data.records
    sel = (rec.array("sequence", object) == sequence) & (rec.array("track_id", int) == track)
    if not sel.any():
        raise ConfigurationError(f"track {track} of sequence {sequence} has no records to plot")
    t = rec.array("timestamp_s")[sel]
    meth = rec.array("method", object)[sel]
    d = rec.array("distance_m")[sel]
    below = np.isin(rec.array("reason", object)[sel], AT_CAP_REASONS)
    t_s = np.unique(t)
    at = np.searchsorted(t_s, t)
    truth = np.full(len(t_s), np.nan)
    truth[at] = rec.array("gt_distance_m")[sel]
    estimates: dict[str, NDArray[np.float64]] = {}
    below_horizon: dict[str, NDArray[np.bool_]] = {}
    for m in data.methods:
        ms = meth == m
        estimates[m] = np.full(len(t_s), np.nan)
        estimates[m][at[ms]] = d[ms]
        below_horizon[m] = np.zeros(len(t_s), bool)
        below_horizon[m][at[ms]] = below[ms]
    return t_s, DistanceSeries(track, truth, estimates, below_horizon)


def figure_tracks(data: ReportData, tracks: Sequence[tuple[str, int]]) -> Figure | None:
    """Distance vs. truth over time for the chosen tracks (:func:`~slopedist.evaluation.plots.
    draw_distance_panel`, as in the demo's plots)."""
    if not tracks:
        return None
    fig = new_figure(10, 2.6 * len(tracks))
    axes = fig.subplots(len(tracks), 1, squeeze=False)[:, 0]
    for ax, (s, track) in zip(axes, tracks):
        draw_distance_panel(ax, *track_series(data, s, track))
        ax.set_title(f"sequence {s}, track {track}", fontsize=9)
        ax.set_ylabel("distance (m)")
    axes[-1].set_xlabel(f"time (s)   ({BELOW_HORIZON_NOTE})")
    lines, labels = axes[0].get_legend_handles_labels()
    fig.legend(lines, labels, fontsize=7, loc="outside right upper")  # not over the data
    return Figure(
        "distance_over_time.png",
        "Estimated distance against the truth over time for chosen tracks "
        "(capped at 80 m; gaps are frames without an estimate).",
        png_bytes(fig),
    )


def figure_error_vs_distance(data: ReportData) -> Figure | None:
    """RMSE and mean signed error per 5 m ground-truth bin, per method."""
    meth = np.asarray(data.records.data["method"], dtype=object)
    d = data.records.array("distance_m")
    g = data.records.array("gt_distance_m")
    scored = np.asarray(data.records.data["scored"], dtype=bool)
    where = "every sequence"
    if data.common is not None:
        scored &= np.isin(
            np.asarray(data.records.data["sequence"], dtype=object), data.common["sequences"]
        )
        where = (
            "the sequences every method ran on (" + compact_names(data.common["sequences"]) + ")"
        )
    if not (scored & np.isfinite(g)).any():
        return None
    edges = np.arange(0.0, 80.0 + ERROR_BIN_M, ERROR_BIN_M)
    centres = 0.5 * (edges[1:] + edges[:-1])
    fig = new_figure(10, 3.6)
    a1, a2 = fig.subplots(1, 2)
    for m in data.methods:
        sel = scored & (meth == m)
        err = d[sel] - g[sel]
        idx = np.digitize(g[sel], edges, right=True) - 1
        rmse = [
            np.sqrt(np.mean(err[idx == b] ** 2)) if (idx == b).sum() >= 5 else np.nan
            for b in range(len(centres))
        ]
        bias = [
            np.mean(err[idx == b]) if (idx == b).sum() >= 5 else np.nan for b in range(len(centres))
        ]
        a1.plot(centres, rmse, "o-", ms=3, color=method_colour(m), label=m)
        a2.plot(centres, bias, "o-", ms=3, color=method_colour(m), label=m)
    a1.set(xlabel="true distance (m)", ylabel="RMSE (m)", title="RMSE per 5 m bin")
    a2.set(
        xlabel="true distance (m)",
        ylabel="mean error (m)",
        title="mean signed error (estimate - truth)",
    )
    a2.axhline(0, color="k", lw=0.8)
    for a in (a1, a2):
        a.grid(alpha=0.3)
    a1.legend(fontsize=7)
    return Figure(
        "error_vs_distance.png",
        f"Error against the true distance per method, pooled over {where} (bins "
        f"with at least 5 targets).",
        png_bytes(fig),
    )


def figure_theta(data: ReportData, max_panels: int = 12) -> Figure | None:
    """θ over time per sequence: every rotation source, the truth source in black."""
    if not len(data.theta):
        return None
    seq = np.asarray(data.theta.data["sequence"], dtype=object)
    src = np.asarray(data.theta.data["source"], dtype=object)
    t = data.theta.array("timestamp_s")
    th = data.theta.array("theta_deg")
    shown = [s for s in data.sequences if (seq == s).any()]
    if data.truth_source is not None:
        with_truth = [s for s in shown if ((seq == s) & (src == data.truth_source)).any()]
        shown = with_truth or shown
    shown = shown[:max_panels]
    cols = min(3, len(shown))
    rows = math.ceil(len(shown) / cols)
    fig = new_figure(4 * cols, 2.3 * rows)
    axes = fig.subplots(rows, cols, squeeze=False)
    for ax in axes.ravel()[len(shown) :]:
        ax.axis("off")
    for ax, s in zip(axes.ravel(), shown):
        # the truth first, wide and grey, so that the sources drawn over it stay visible
        for source in sorted(set(src[seq == s]), key=lambda x: x != data.truth_source):
            sel = (seq == s) & (src == source)
            truth = source == data.truth_source
            ax.plot(
                t[sel],
                th[sel],
                "-",
                lw=3.0 if truth else 1.0,
                color="0.6" if truth else None,
                label=(source if source == "truth" else f"{source} (truth)") if truth else source,
            )
        ax.set_title(f"sequence {s}", fontsize=9)
        ax.grid(alpha=0.3)
    axes[0, 0].set_ylabel("θ (deg)")
    axes[0, 0].legend(fontsize=7)
    axes[-1, 0].set_xlabel("time (s)")
    what = f"against {data.truth_name()}" if data.truth_source else "(no truth of θ in this source)"
    return Figure(
        "theta_over_time.png",
        f"Ego road gradient θ (eq. 4, 1 s look-back) over time {what}.",
        png_bytes(fig),
    )


def _series(data: ReportData, sel: NDArray[np.bool_]) -> dict[str, NDArray[np.float64]]:
    """The selected records in time order: time, distance, 1σ and upper bound."""
    rec = data.records
    t = rec.array("timestamp_s")[sel]
    order = np.argsort(t, kind="stable")
    out = {"t": t[order]}
    for key in ("distance_m", "sigma_m", "bound_m"):
        out[key] = rec.array(key)[sel][order]
    return out


def _draw_method(ax: Any, name: str, s: dict[str, NDArray[np.float64]], bounds_label: str) -> float:
    """One method's distances of a track (line, ±1σ band, upper bounds as open triangles);
    returns the largest value drawn (metres, 0 when none)."""
    colour = method_colour(name)
    d, sigma, bound = s["distance_m"], s["sigma_m"], s["bound_m"]
    label = name if np.isfinite(d).any() else "_"  # only bounds: no line to name
    ax.plot(s["t"], d, color=colour, lw=1.3, marker=".", ms=3, label=label)
    band = np.isfinite(d) & np.isfinite(sigma)
    if band.any():
        low, high = np.where(band, d - sigma, np.nan), np.where(band, d + sigma, np.nan)
        ax.fill_between(s["t"], low, high, color=colour, alpha=0.22, lw=0, label=f"{name} ±1σ")
    has_bound = np.isfinite(bound)
    if has_bound.any():
        ax.plot(
            s["t"][has_bound],
            bound[has_bound],
            "v",
            mfc="none",
            color=colour,
            ms=4,
            label=bounds_label,
        )
    drawn = np.concatenate([d, np.where(band, d + sigma, np.nan), bound])
    return float(np.nanmax(drawn)) if np.isfinite(drawn).any() else 0.0


def draw_track_panel(ax: Any, data: ReportData, sequence: str, track: int) -> list[str]:
    """One track's estimated distance over time on the matplotlib axes ``ax``, without a
    truth: every method that has records of it, a y scale of its own from 0 to a little over
    the largest value drawn, the ±1σ band of a method that gives one, upper bounds as open
    triangles, the per-track table's distance threshold dotted, and the legend outside the
    axes (right). Returns what the caption must explain.

    Raises:
        ConfigurationError: the track has no records.
    """
    rec = data.records
    sel = (rec.array("sequence", object) == sequence) & (rec.array("track_id", int) == track)
    if not sel.any():
        raise ConfigurationError(f"track {track} of sequence {sequence} has no records to plot")
    meth = rec.array("method", object)
    top, has_band, has_bound = 0.0, False, False
    for m in [m for m in data.methods if (sel & (meth == m)).any()]:
        s = _series(data, sel & (meth == m))
        top = max(top, _draw_method(ax, m, s, "upper bound" if not has_bound else "_"))
        has_band |= bool((np.isfinite(s["distance_m"]) & np.isfinite(s["sigma_m"])).any())
        has_bound |= bool(np.isfinite(s["bound_m"]).any())
    top = 1.15 * top if top > 0 else 1.0
    if data.near_m < top:
        ax.axhline(data.near_m, color="0.35", lw=0.8, ls=":")
        ax.annotate(
            f"{data.near_m:g} m",
            (1.0, data.near_m),
            xycoords=("axes fraction", "data"),
            xytext=(-2, 2),
            textcoords="offset points",
            ha="right",
            va="bottom",
            fontsize=7,
            color="0.35",
        )
    ax.set_ylim(0.0, top)
    ax.set(xlabel="time (s)", ylabel="distance (m)")
    where = f", {sequence}" if len(data.sequences) > 1 else ""
    ax.set_title(f"track {track}{where}", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    return [
        *(["band: ±1σ, the method's own uncertainty"] if has_band else []),
        *(["▽: an upper bound, for a box cut by the image bottom"] if has_bound else []),
        *([f"dotted: {data.near_m:g} m"] if data.near_m < top else []),
    ]


def figure_track(data: ReportData, sequence: str, track: int) -> Figure:
    """A small plot of one track's estimated distance over time (:func:`draw_track_panel`),
    placed after the per-track table.

    Raises:
        ConfigurationError: the track has no records.
    """
    fig = new_figure(5.6, 2.3)
    extras = draw_track_panel(fig.subplots(), data, sequence, track)
    points = set(data.references.values())
    to = f" to {reference_words(points.pop())}" if len(points) == 1 else ""
    where = f" of {sequence}" if len(data.sequences) > 1 else ""
    return Figure(
        f"track_{_file_part(sequence)}_{track}.png",
        f"Track {track}{where}: estimated distance{to} over time"
        + (f" ({'; '.join(extras)})" if extras else "")
        + ".",
        png_bytes(fig),
        after="tracks",
        small=True,
    )


def _file_part(name: str) -> str:
    """``name`` with every character that is not a letter, digit, ``-`` or ``_`` as ``_``."""
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in name)


def report_figures(
    data: ReportData, tracks: Sequence[tuple[str, int]] | None, n_tracks: int
) -> list[Figure]:
    """Every figure of the report (matplotlib on the Agg canvas, no display): with a truth the
    chosen tracks against it (``tracks``, else :func:`choose_tracks` of ``n_tracks``) and the
    error by distance; without one a plot per track (``tracks``, else the
    :data:`LEADING_TRACK_PLOTS` :func:`~slopedist.evaluation.report.track_summary.
    leading_tracks`); then θ."""
    if data.has_truth:
        chosen = list(tracks) if tracks else choose_tracks(data, n_tracks)
        figs = [figure_tracks(data, chosen), figure_error_vs_distance(data)]
    else:
        chosen = list(tracks) if tracks else leading_tracks(data, LEADING_TRACK_PLOTS)
        figs = [figure_track(data, s, t) for s, t in chosen]
    figs.append(figure_theta(data))
    return [f for f in figs if f is not None]
