"""``slopedist log``: what a drive log (ROS 1 bag, ROS 2 bag, MCAP) holds."""

from __future__ import annotations

import math
from pathlib import Path

import click

from slopedist.cli.choice import SuggestingGroup
from slopedist.io.formatting import dumps_json
from slopedist.io.rosbag import log_topics


@click.group("log", cls=SuggestingGroup)
def log_group() -> None:
    """Drive logs: ROS 1 bags, ROS 2 bags (sqlite3 or MCAP) and MCAP files."""


@log_group.command("info")
@click.argument("log", type=click.Path(path_type=Path))
@click.option("--json", "as_json", is_flag=True, help="Print the topics as JSON.")
def info(log: Path, as_json: bool) -> None:
    """List the topics of LOG with their message types, counts and mean rates (Hz)."""
    topics = log_topics(log)
    if as_json:
        rows = [
            {
                "topic": t.topic,
                "type": t.msgtype,
                "count": t.count,
                "rate_hz": t.rate_hz,
                "first_ns": t.first_ns,
                "last_ns": t.last_ns,
            }
            for t in topics
        ]
        click.echo(dumps_json(rows))
        return
    width = max([len(t.topic) for t in topics] + [5])
    twidth = max([len(t.msgtype) for t in topics] + [4])
    click.echo(f"{'topic':<{width}}  {'type':<{twidth}}  {'count':>7}  {'rate_hz':>8}")
    for t in topics:
        rate = f"{t.rate_hz:8.2f}" if math.isfinite(t.rate_hz) else f"{'-':>8}"
        click.echo(f"{t.topic:<{width}}  {t.msgtype:<{twidth}}  {t.count:>7}  {rate}")
    if topics:
        used = [t for t in topics if t.count]
        span = (max(t.last_ns for t in used) - min(t.first_ns for t in used)) / 1e9 if used else 0
        click.echo(f"{len(topics)} topics, {sum(t.count for t in topics)} messages, {span:.3f} s")
