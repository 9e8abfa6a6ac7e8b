"""``slopedist convert``: box files between the layouts detectors and trackers write."""

from __future__ import annotations

from pathlib import Path

import click

from slopedist.cli.choice import Choice
from slopedist.cli.options import FINITE_FLOAT, parse_size
from slopedist.core.limits import MAX_INDEX
from slopedist.io.detections.convert import (
    WRITABLE,
    BoxFileOptions,
    BoxFormat,
    convert_boxes,
    target_format_of,
)
from slopedist.io.outputs import check_outputs_spare_inputs


@click.command("convert")
@click.argument("source", type=click.Path(exists=True, path_type=Path))
@click.argument("target", type=click.Path(path_type=Path))
@click.option(
    "--from",
    "source_format",
    type=Choice([f.value for f in BoxFormat]),
    default=BoxFormat.AUTO.value,
    show_default=True,
    help="Layout of SOURCE (auto: from its content; a folder is YOLO, .json is COCO).",
)
@click.option(
    "--to",
    "target_format",
    type=Choice([BoxFormat.AUTO.value, *(f.value for f in WRITABLE)]),
    default=BoxFormat.AUTO.value,
    show_default=True,
    help="Layout of TARGET (auto: COCO for a .json file, else slopedist CSV; YOLO: a folder).",
)
@click.option("--image-size", help="WIDTHxHEIGHT of the frames, pixels (YOLO in or out).")
@click.option(
    "--coco-images",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    help="COCO dataset JSON whose 'images' map image ids to frames (default: id = frame).",
)
@click.option(
    "--frame-base",
    type=click.IntRange(0, MAX_INDEX),
    help="Number of the first frame in MOT (default 1) or YOLO (default 0) files.",
)
@click.option("--min-score", type=FINITE_FLOAT, help="Drop boxes scored below this.")
def convert(
    source: Path,
    target: Path,
    source_format: str,
    target_format: str,
    image_size: str | None,
    coco_images: Path | None,
    frame_base: int | None,
    min_score: float | None,
) -> None:
    """Convert box file SOURCE (slopedist CSV, KITTI, PointRCNN, MOTChallenge, COCO JSON, YOLO
    folder) into TARGET (COCO if .json, else slopedist CSV; or --to)."""
    check_outputs_spare_inputs([target], [source, coco_images])
    options = BoxFileOptions(
        parse_size(image_size, option="--image-size"), coco_images, frame_base, min_score
    )
    layout = target_format_of(target, target_format).value
    n_read, n_left, unkept = convert_boxes(source, target, source_format, layout, options)
    note = f", {n_left} left out (class not in the '{layout}' class list)" if n_left else ""
    click.echo(f"{n_read} boxes from {source} written to {target}{note}", err=True)
    for line in unkept:
        click.echo(f"not kept: {line}", err=True)
