"""Rows of a box file that a reader leaves out, counted by reason.

The readers of :mod:`slopedist.io.detections.formats` leave out rows that are no vehicle's box:
MOTChallenge ``gt.txt`` rows flagged 0 or of a class that is no object, COCO annotations of a
category not in the class map or of a crowd, YOLO labels of a class not in the class map. They
count each in a :class:`DroppedBoxes`; :func:`~slopedist.io.detections.convert.read_boxes` (behind
every command that reads a box file) logs one warning line per file when any row was left out,
and ``slopedist run`` writes the counts into ``run.json`` (``dropped_boxes``). Rows below a
``--score`` threshold are not counted: they are left out because the user asked.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path

_log = logging.getLogger(__name__)

SHOWN_REASONS = 5
"""Reasons a warning names (the most frequent first); the rest are counted as "N more"."""


@dataclass
class DroppedBoxes:
    """Rows of one box file a reader left out.

    Attributes:
        reasons: ``{reason: rows}``, e.g. ``{"category_id 1 (not in the class map)": 25}``.
    """

    reasons: dict[str, int] = field(default_factory=dict)

    def add(self, reason: str) -> None:
        """Count one row left out for ``reason``."""
        self.reasons[reason] = self.reasons.get(reason, 0) + 1

    @property
    def count(self) -> int:
        """Rows left out, all reasons."""
        return sum(self.reasons.values())

    def message(self, source: str | Path, kept: int) -> str:
        """``"<source>: dropped D of N box rows (P %): <count> <reason>, ..."`` (``kept``: the
        rows the reader returned)."""
        total = self.count + kept
        ranked = sorted(self.reasons.items(), key=lambda item: (-item[1], item[0]))
        shown = ", ".join(f"{n} {reason}" for reason, n in ranked[:SHOWN_REASONS])
        more = len(ranked) - SHOWN_REASONS
        tail = f" and {more} more reason(s)" if more > 0 else ""
        percent = 100.0 * self.count / total if total else 0.0
        return (
            f"{source}: dropped {self.count} of {total} box rows ({percent:.0f} %): {shown}{tail}"
        )

    def warn(self, source: str | Path, kept: int) -> None:
        """Log :meth:`message` as one warning (logger ``slopedist.io.detections.dropped``) when a
        row was left out."""
        if self.reasons:
            _log.warning("warning: %s", self.message(source, kept))
