"""Overlay videos: H.264 yuv420p fragmented MP4, frame times kept, playable after a kill."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from slopedist.io.overlay import OverlayWriter, even_size

av = pytest.importorskip("av")

REPO = Path(__file__).resolve().parents[2]


def decoded(path: Path) -> tuple[str, str, list[float]]:
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        times = [float(f.pts * f.time_base) for f in container.decode(stream)]
        return stream.codec_context.name, stream.codec_context.pix_fmt, times


def test_mp4_is_browser_h264_with_the_frame_times(tmp_path: Path) -> None:
    writer = OverlayWriter(tmp_path / "o.mp4", fps=10.0)
    times = [0.0, 0.1, 0.25, 0.3]
    for k, t in enumerate(times):
        writer.write(k, np.full((375, 1242, 3), 50 * k, np.uint8), t)  # odd height: padded
    writer.write_placeholder(4, "frame 4: missing")  # no time: 4 / fps
    writer.close()
    codec, pix_fmt, got = decoded(tmp_path / "o.mp4")
    assert (codec, pix_fmt) == ("h264", "yuv420p")
    assert got == pytest.approx([*times, 0.4])
    data = (tmp_path / "o.mp4").read_bytes()
    assert b"moof" in data  # fragmented: playable while written


def test_even_size_pads_one_black_row_and_column() -> None:
    image = np.full((3, 5, 3), 200, np.uint8)
    padded = even_size(image)
    assert padded.shape == (4, 6, 3)
    assert (padded[:3, :5] == 200).all() and (padded[3] == 0).all() and (padded[:, 5] == 0).all()


def test_killed_writer_leaves_a_playable_file(tmp_path: Path) -> None:
    target = tmp_path / "killed.mp4"
    script = textwrap.dedent(
        f"""
        import sys, time
        import numpy as np
        sys.path.insert(0, {str(REPO / "src")!r})
        from slopedist.io.overlay import OverlayWriter
        w = OverlayWriter({str(target)!r}, 10.0)
        for k in range(10_000):
            w.write(k, np.full((48, 64, 3), k % 250, np.uint8))
            print(k, flush=True)
            time.sleep(0.005)
        """
    )
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    for line in proc.stdout:
        if int(line) >= 35:
            break
    proc.kill()
    proc.wait()
    codec, _, times = decoded(target)
    assert codec == "h264"
    # everything up to the last finished one-second fragment plays, at the right times
    assert len(times) >= 30
    assert times == pytest.approx([k / 10 for k in range(len(times))])
