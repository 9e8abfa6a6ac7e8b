"""``slopedist simulate``: render a synthetic hill scenario with exact ground truth."""

from __future__ import annotations

from pathlib import Path

import click
from tqdm import tqdm

from slopedist.cli.choice import Choice
from slopedist.core.errors import ConfigurationError
from slopedist.io.outputs import OutputFolder
from slopedist.synthetic.export import (
    SIMULATION_NAMES,
    DepthFormat,
    refuse_stale_frames,
    write_simulation,
)
from slopedist.synthetic.noise import BoxNoiseSpec
from slopedist.synthetic.scenarios import (
    builtin_text,
    describe_builtins,
    load_scenario,
)
from slopedist.synthetic.sequence import SyntheticSequence


@click.command("simulate")
@click.argument("scenario", required=False)
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    help="Output folder (created).",
)
@click.option("--list", "list_only", is_flag=True, help="List the built-in scenarios and exit.")
@click.option(
    "--depth",
    type=Choice([d.value for d in DepthFormat]),
    default="png",
    show_default=True,
    help="True depth maps: KITTI depth PNG, float32 .npy, or none.",
)
@click.option("--no-images", is_flag=True, help="Do not write the rendered frames.")
@click.option(
    "--exact-boxes",
    is_flag=True,
    help="boxes.csv gets the exact boxes (no detector noise, no misses).",
)
@click.option(
    "--frames", "max_frames", type=click.IntRange(min=1), help="Write only the first N frames."
)
@click.option(
    "--force",
    is_flag=True,
    help="Write into a folder that holds a previous simulation (or files of its names).",
)
def simulate(
    scenario: str | None,
    out_dir: Path | None,
    list_only: bool,
    depth: str,
    no_images: bool,
    exact_boxes: bool,
    max_frames: int | None,
    force: bool,
) -> None:
    """Render SCENARIO (a built-in name or a TOML file) with its ground truth to --out.

    The folder then works with the other commands, e.g.
    ``slopedist estimate --calib OUT/calib.txt --poses OUT/poses.txt --boxes OUT/boxes.csv``.
    """
    if list_only:
        for item in describe_builtins():
            click.echo(f"{item.name:22s} {item.description}")
        return
    if scenario is None:
        raise click.UsageError(
            "give a SCENARIO (a built-in name or a .toml file); see slopedist simulate --list"
        )
    if out_dir is None:
        raise click.UsageError("give the output folder with --out DIR")
    sc = load_scenario(scenario)
    with OutputFolder(out_dir).lock():
        held = [name for name in SIMULATION_NAMES if (out_dir / name).exists()]
        if held and not force:  # a simulation, or a drive's own calib.txt, boxes.csv, frames
            raise ConfigurationError(
                f"{out_dir} already holds {', '.join(held)} (a simulation or other data that "
                "would be overwritten); choose another --out or add --force"
            )
        seq = SyntheticSequence(sc, BoxNoiseSpec.exact() if exact_boxes else None)
        total = len(seq) if max_frames is None else min(len(seq), max_frames)
        refuse_stale_frames(out_dir, total, not no_images, DepthFormat(depth))
        path = Path(scenario)
        text = path.read_text(encoding="utf-8") if path.is_file() else builtin_text(sc.name)
        with tqdm(total=total, unit="frame", desc=f"simulate {sc.name}", dynamic_ncols=True) as bar:
            info = write_simulation(
                seq,
                out_dir,
                text,
                depth=DepthFormat(depth),
                images=not no_images,
                max_frames=max_frames,
                on_frame=lambda _k: bar.update(1),
            )
    click.echo(
        f"wrote {info['frames']} frames of '{sc.name}' to {out_dir} "
        f"(camera height {info['camera_height_m']:g} m)"
    )
    if not info["detections"]:  # a road without traffic is a valid scene: say what it gives
        why = "the scenario has no [[target]]" if not sc.targets else "no target was detected"
        click.echo(f"note: boxes.csv holds no box ({why}); every other file is written")
    camera = f"--height {info['camera_height_m']:g} --mount-angle {info['mount_angle_deg']:g}"
    click.echo(
        f"next: slopedist estimate --calib {out_dir}/calib.txt --poses "
        f"{out_dir}/poses.txt --boxes {out_dir}/boxes.csv {camera}"
    )
    if info["images"]:
        click.echo(
            f"  or, from the pixels: slopedist run {out_dir}/image_02 --calib "
            f"{out_dir}/calib.txt --boxes {out_dir}/boxes.csv --timestamps "
            f"{out_dir}/times.txt {camera} --method paper --out {out_dir}/run_paper; "
            f"then slopedist report {out_dir}/run_paper"
        )
