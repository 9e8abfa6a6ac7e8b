"""Which files of an image folder are frames, and which frame each one is.

The rule (also in :mod:`slopedist.io.frames`): image files are ``*.png``, ``*.jpg``, ``*.jpeg``
(any case) whose name does not start with ``.``. When at least one file name is a number
(ASCII digits only: ``0000000000.png``, ``000123.jpg``), the numbered files are the frames and
the number is the frame index; every other image file (``0000000004b.png``, ``-1.png``) is
skipped and reported, never renumbering the folder. A gap of more than
:data:`~slopedist.core.limits.MAX_FRAME_GAP` frame numbers, or a number over
:data:`~slopedist.core.limits.MAX_INDEX`, is an error naming the file. When no file name is a
number,
the frames are numbered 0, 1, ... in sorted name order. Hidden files (macOS ``._0001.png``) are
always skipped and reported.
"""

from __future__ import annotations

import itertools
import logging
import re
from dataclasses import dataclass
from pathlib import Path

from slopedist.core.errors import InputFileError, MissingInputError
from slopedist.core.limits import MAX_FRAME_GAP, MAX_INDEX

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
"""File name endings an image folder is read from (case-insensitive)."""

_FRAME_NUMBER = re.compile(r"[0-9]+")
"""A file stem that is a frame number (ASCII digits only: no sign, letters or other digits)."""

_log = logging.getLogger(__name__)


def frame_number(stem: str) -> int | None:
    """The frame index a file with this stem has in an image folder that has numbered files
    (``000123`` → 123), or None when the stem is not a frame number."""
    return int(stem) if _FRAME_NUMBER.fullmatch(stem) else None


@dataclass(frozen=True)
class FolderFrames:
    """The frames of an image folder (see :func:`list_frame_files`).

    Attributes:
        files: ``{frame index: file}``.
        numbered: True when the indices are the numbers in the file names.
        skipped: ``(file name, reason)`` of the image files that are not frames.
    """

    files: dict[int, Path]
    numbered: bool
    skipped: tuple[tuple[str, str], ...]


def _image_files(folder: Path) -> list[Path]:
    if not folder.is_dir():
        raise MissingInputError(f"frame folder not found: {folder}")
    return sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file())


def list_frame_files(folder: str | Path) -> FolderFrames:
    """The frame files of an image folder, by the rule of the module docstring.

    Skipped files are logged as one warning (logger ``slopedist.io.frames``).

    Raises:
        MissingInputError: no such folder, or no frame file in it.
        InputFileError: two files with one frame number (``5.png``, ``005.png``), a number over
            :data:`~slopedist.core.limits.MAX_INDEX`, or a gap over
            :data:`~slopedist.core.limits.MAX_FRAME_GAP` (naming the file after it).
    """
    folder = Path(folder)
    images = _image_files(folder)
    skipped = [(p.name, "hidden file") for p in images if p.name.startswith(".")]
    visible = [p for p in images if not p.name.startswith(".")]
    numbered = [p for p in visible if _FRAME_NUMBER.fullmatch(p.stem)]
    if numbered:
        skipped += [(p.name, "name is not a frame number") for p in visible if p not in numbered]
        files = _numbered_files(numbered)
    else:
        files = dict(enumerate(visible))
    if not files:
        raise MissingInputError(
            f"no image files ({', '.join(IMAGE_SUFFIXES)}) in frame folder {folder}"
        )
    if skipped:
        shown = ", ".join(f"{name} ({why})" for name, why in skipped[:5])
        more = f" and {len(skipped) - 5} more" if len(skipped) > 5 else ""
        _log.warning(
            "warning: %s: skipped %d image file(s) that are not frames: %s%s",
            folder,
            len(skipped),
            shown,
            more,
        )
    return FolderFrames(files, bool(numbered), tuple(skipped))


def _numbered_files(paths: list[Path]) -> dict[int, Path]:
    """``{number: file}`` of files named by a frame number, checking duplicates and gaps."""
    files: dict[int, Path] = {}
    for p in paths:
        k = int(p.stem)
        if k > MAX_INDEX:
            raise InputFileError(p, f"frame number {k} is over the largest accepted {MAX_INDEX}")
        if k in files:
            raise InputFileError(p, f"frame number {k} also used by {files[k].name}")
        files[k] = p
    order = sorted(files)
    for before, after in itertools.pairwise(order):
        if after - before - 1 > MAX_FRAME_GAP:
            raise InputFileError(
                files[after],
                f"frame number {after} follows {before}: {after - before - 1} frames missing "
                f"(more than {MAX_FRAME_GAP}); is this file part of the sequence? Rename or "
                "remove it",
            )
    return files
