"""Summary lines about a command's per-target records (``run`` and ``estimate``)."""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

from slopedist.estimators.base import EstimateStatus, MissingReason


def not_vehicles_line(
    classes: Mapping[str, int], records: int, with_distance: int, shown: int = 5
) -> str:
    """The summary line of the ``classes`` (``{name: rows}``) of boxes that are not vehicles,
    naming the ``shown`` most frequent (a class meant as a vehicle, e.g. a detector's id ``2``,
    is seen at once); a warning when none of the ``records`` rows got a distance
    (``with_distance``: rows ``ok`` or ``upper_bound``), whose advice is ``--vehicle-classes``
    only when every row is of such a class (rows of vehicle classes lacked something else)."""
    ranked = sorted(classes.items(), key=lambda kv: (-kv[1], kv[0]))
    names = ", ".join(f"'{name}' ({n})" for name, n in ranked[:shown])
    more = f" and {len(ranked) - shown} more" if len(ranked) > shown else ""
    total = sum(classes.values())
    if with_distance == 0:
        advice = (
            "name the vehicle classes with --vehicle-classes"
            if total >= records
            else f"the reasons of the other {records - total} rows say what they lacked"
        )
        return (
            f"warning: no box got a distance; {total} of {records} are of a class that is not a "
            f"vehicle: {names}{more} (missing, reason not_a_vehicle); {advice}"
        )
    return (
        f"{total} boxes are not of a vehicle class ({names}{more}; missing, reason "
        "not_a_vehicle; see --vehicle-classes)"
    )


@dataclass
class RecordTally:
    """Counts of the record rows that pass through :meth:`count` (``estimate``'s summary)."""

    records: int = 0
    ok: int = 0
    upper_bounds: int = 0
    not_vehicle_classes: dict[str, int] = field(default_factory=dict)

    def count(self, rows: Iterable[dict[str, Any]]) -> Iterator[dict[str, Any]]:
        """``rows`` unchanged, counted."""
        for row in rows:
            self.records += 1
            self.ok += row["status"] == EstimateStatus.OK.value
            self.upper_bounds += row["status"] == EstimateStatus.UPPER_BOUND.value
            if row["reason"] == MissingReason.NOT_A_VEHICLE.value:
                name = str(row["class"])
                self.not_vehicle_classes[name] = self.not_vehicle_classes.get(name, 0) + 1
            yield row

    def lines(self, out: object | None) -> list[str]:
        """The summary: the records written to ``out`` (a file; None: standard output, no
        line), and the boxes of classes that are not vehicles."""
        lines = []
        if out is not None:
            lines.append(
                f"wrote {self.records} records ({self.ok} ok, {self.upper_bounds} upper bounds) "
                f"to {out}"
            )
        if self.not_vehicle_classes:
            lines.append(
                not_vehicles_line(
                    self.not_vehicle_classes, self.records, self.ok + self.upper_bounds
                )
            )
        return lines
