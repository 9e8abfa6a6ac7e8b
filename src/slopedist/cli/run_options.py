"""The options of ``slopedist run`` that ``slopedist batch`` takes as batch-wide values: the
drive log's image topic, the offline mode, the overlay and the exports."""

from __future__ import annotations

import click

from slopedist.cli.choice import Choice
from slopedist.streaming.config import OverlayFormat, RunExport
from slopedist.streaming.step import RecordColumns

image_topic_option = click.option(
    "--image-topic",
    default=None,
    help="Drive log (.bag, .mcap, .db3, ROS 2 bag folder): the sensor_msgs/Image or "
    "CompressedImage topic (see: slopedist log info LOG).",
)
run_offline_option = click.option(
    "--offline",
    is_flag=True,
    help="The method's offline mode (ours → ours-offline: smoothed over the whole drive, for "
    "log analysis): records.csv is written when the drive ends; the overlay, frames.csv and "
    "the MCAP export show the causal pass as the frames come.",
)
export_option = click.option(
    "--export",
    "exports",
    type=Choice([e.value for e in RunExport]),
    multiple=True,
    help="Also write OUT/run.mcap (Foxglove schemas) and/or OUT/trajectory.tum (rotations, "
    "for evo). Repeatable.",
)
overlay_option = click.option(
    "--overlay", is_flag=True, help="Also write annotated frames (paper Fig. 3 style)."
)
overlay_format_option = click.option(
    "--overlay-format",
    type=Choice([f.value for f in OverlayFormat]),
    default=OverlayFormat.MP4.value,
    show_default=True,
    help="Overlay as OUT/overlay.mp4 or as PNG files in OUT/overlay/.",
)
columns_option = click.option(
    "--columns",
    type=Choice([c.value for c in RecordColumns]),
    default=RecordColumns.DEFAULT.value,
    show_default=True,
    help="Columns of records.csv: default (frame, time, track, box, distance, σ, status, "
    "speed, TTC: docs/usage.md#columns-of-recordscsv) or all (with the method's diagnostics).",
)
