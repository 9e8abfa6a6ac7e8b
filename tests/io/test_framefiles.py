"""The frame-folder rule: stray names never renumber a folder, huge gaps are errors."""

from __future__ import annotations

import logging
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from slopedist.core.errors import InputFileError, MissingInputError
from slopedist.core.limits import MAX_FRAME_GAP, MAX_INDEX
from slopedist.io.framefiles import list_frame_files
from slopedist.io.frames import FrameStatus, open_frames

STRAYS = [
    "0000000004b.png",
    "-1.png",
    "._0000000001.png",
    ".hidden.png",
    "x.jpg",
    "4.5.png",
    "٣.png",
]


def _folder(root: Path, indices: list[int], strays: list[str] = ()) -> Path:  # type: ignore[assignment]
    root.mkdir(parents=True, exist_ok=True)
    for k in indices:
        assert cv2.imwrite(str(root / f"{k:010d}.png"), np.full((8, 12, 3), k % 256, np.uint8))
    for name in strays:
        (root / name).write_bytes(b"whatever")
    return root


def test_stray_names_are_skipped_and_reported_never_renumbering(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    root = _folder(tmp_path / "f", [0, 1, 2, 3, 5], STRAYS)
    with caplog.at_level(logging.WARNING, logger="slopedist.io.framefiles"):
        listing = list_frame_files(root)
    assert sorted(listing.files) == [0, 1, 2, 3, 5] and listing.numbered
    assert {name for name, _ in listing.skipped} == set(STRAYS)
    assert dict(listing.skipped)["._0000000001.png"] == "hidden file"
    assert dict(listing.skipped)["-1.png"] == "name is not a frame number"
    assert (
        "skipped 7 image file(s) that are not frames" in caplog.text and "and 2 more" in caplog.text
    )
    frames = list(open_frames(root))
    assert [f.index for f in frames] == [0, 1, 2, 3, 4, 5]
    assert [f.source for f in frames if f.ok] == [f"{k:010d}.png" for k in (0, 1, 2, 3, 5)]
    assert frames[4].status is FrameStatus.MISSING
    assert all(int(f.image[0, 0, 0]) == f.index % 256 for f in frames if f.ok)  # the right pixels


@settings(max_examples=30, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    indices=st.sets(st.integers(0, 60), min_size=1, max_size=8),
    strays=st.lists(st.sampled_from(STRAYS), max_size=3, unique=True),
)
def test_any_stray_leaves_every_frame_at_its_number(
    tmp_path_factory: pytest.TempPathFactory, indices: set[int], strays: list[str]
) -> None:
    root = _folder(tmp_path_factory.mktemp("f"), sorted(indices), strays)
    listing = list_frame_files(root)
    assert {k: p.name for k, p in listing.files.items()} == {k: f"{k:010d}.png" for k in indices}


def test_huge_gap_is_an_error_naming_the_file(tmp_path: Path) -> None:
    root = _folder(tmp_path / "f", list(range(0, 101)))
    (root / "0000500000.png").write_bytes(b"x")
    with pytest.raises(InputFileError, match=r"0000500000\.png: frame number 500000 follows 100"):
        open_frames(root)
    (root / "0000500000.png").unlink()
    (root / "9999999999.png").write_bytes(b"x")
    with pytest.raises(InputFileError, match=r"9999999999\.png: frame number 9999999999 is over"):
        open_frames(root)


def test_gap_limit_and_index_limit(tmp_path: Path) -> None:
    ok = _folder(tmp_path / "ok", [0, MAX_FRAME_GAP + 1])
    assert sorted(list_frame_files(ok).files) == [0, MAX_FRAME_GAP + 1]
    bad = _folder(tmp_path / "bad", [0, MAX_FRAME_GAP + 2])
    with pytest.raises(InputFileError, match=f"{MAX_FRAME_GAP + 1} frames missing"):
        list_frame_files(bad)
    huge = tmp_path / "huge"
    huge.mkdir()
    (huge / f"{MAX_INDEX + 1}.png").write_bytes(b"x")
    with pytest.raises(InputFileError, match="over the largest accepted"):
        list_frame_files(huge)


def test_only_hidden_files_is_no_frames(tmp_path: Path) -> None:
    root = tmp_path / "f"
    root.mkdir()
    (root / "._000001.png").write_bytes(b"x")
    with pytest.raises(MissingInputError, match="no image files"):
        list_frame_files(root)


def test_folder_without_numbers_keeps_sorted_order(tmp_path: Path) -> None:
    root = _folder(tmp_path / "f", [], ["b.png", "a.png", "._a.png"])
    listing = list_frame_files(root)
    assert {k: p.name for k, p in listing.files.items()} == {0: "a.png", 1: "b.png"}
    assert not listing.numbered and listing.skipped == (("._a.png", "hidden file"),)
