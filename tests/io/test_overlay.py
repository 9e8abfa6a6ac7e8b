"""Overlay videos: H.264 yuv420p fragmented MP4, frame times kept, playable after a kill."""

from __future__ import annotations

import re
import shutil
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


def killed_overlay(target: Path, stop_after: int) -> None:
    """Write an overlay in a child process (frame k grey level k, at k / 10 s) and kill it with
    SIGKILL once it has written ``stop_after`` frames."""
    script = textwrap.dedent(
        f"""
        import sys, time
        import numpy as np
        sys.path.insert(0, {str(REPO / "src")!r})
        from slopedist.io.overlay import OverlayWriter
        w = OverlayWriter({str(target)!r}, 10.0)
        for k in range(10_000):
            w.write(k, np.full((48, 64, 3), 4 * k % 250, np.uint8))
            print(k, flush=True)
            time.sleep(0.005)
        """
    )
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    for line in proc.stdout:
        if int(line) >= stop_after:
            break
    proc.kill()
    proc.wait()


def test_killed_writer_leaves_a_playable_file(tmp_path: Path) -> None:
    target = tmp_path / "killed.mp4"
    killed_overlay(target, 35)
    codec, _, times = decoded(target)
    assert codec == "h264"
    # everything up to the last finished one-second fragment plays, at the right times
    assert len(times) >= 30
    assert times == pytest.approx([k / 10 for k in range(len(times))])


# --- in a browser ---------------------------------------------------------------------------

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")

PAGE = """<!doctype html><html><body data-state="start">
<video id="v" src="VIDEO" muted preload="auto"></video><canvas id="c"></canvas>
<script>
const v = document.getElementById("v"), b = document.body, c = document.getElementById("c");
const times = TIMES, seen = [];
v.addEventListener("error", () => { b.dataset.state = "error"; b.dataset.error = v.error.code; });
function seek(t) {  // drawn once the frame sought is shown: "seeked" may come before it is
  v.requestVideoFrameCallback(draw); v.currentTime = t;
}
function draw() {
  c.width = v.videoWidth; c.height = v.videoHeight;
  const g = c.getContext("2d"); g.drawImage(v, 0, 0);
  seen.push(g.getImageData(8, 8, 1, 1).data[0]);
  if (seen.length < times.length) { seek(times[seen.length]); return; }
  b.dataset.grey = seen.join(","); b.dataset.state = "done";
}
v.addEventListener("loadeddata", () => { b.dataset.duration = v.duration; seek(times[0]); });
let ticks = 0;  // busy ticks let the media thread work while virtual time waits
function spin() {
  let x = 0; for (let i = 0; i < 3e6; i++) { x += Math.sqrt(i); }
  if (b.dataset.state === "start" && ++ticks < 400) setTimeout(spin, 10);
}
setTimeout(spin, 10);
</script></body></html>"""


def play_in_chromium(video: Path, times: list[float], tmp_path: Path) -> dict[str, str]:
    """Open ``video`` in a ``<video>`` element of headless Chromium, seek to ``times`` (s) and
    return the page's findings: duration, state and the red level of a pixel at each time."""
    page = tmp_path / "play.html"
    page.write_text(PAGE.replace("VIDEO", video.name).replace("TIMES", repr(times)))
    cmd = [
        str(CHROMIUM),
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--no-first-run",
        "--allow-file-access-from-files",  # file:// video into a readable canvas
        f"--user-data-dir={tmp_path / 'profile'}",
        "--virtual-time-budget=30000",
        "--dump-dom",
        page.as_uri(),
    ]
    dom = subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=False).stdout
    body = re.search(r"<body[^>]*>", dom)
    assert body is not None, f"no <body> in Chromium's DOM dump: {dom[:300]!r}"
    return dict(re.findall(r'data-([a-z]+)="([^"]*)"', body.group(0)))


needs_chromium = pytest.mark.skipif(
    CHROMIUM is None,
    reason="headless Chromium not installed (Debian package 'chromium'; .ci/run installs it)",
)


@needs_chromium
def test_overlay_plays_in_a_browser_video_element(tmp_path: Path) -> None:
    writer = OverlayWriter(tmp_path / "o.mp4", fps=10.0)
    times = [0.0, 0.1, 0.25, 0.3, 1.0, 1.1, 2.0]  # variable frame rate
    for k, t in enumerate(times):
        writer.write(k, np.full((375, 1242, 3), 30 * k, np.uint8), t)
    writer.close()
    seen = play_in_chromium(tmp_path / "o.mp4", [0.05, 0.27, 1.05, 2.05], tmp_path)
    assert seen.get("state") == "done", seen
    assert float(seen["duration"]) == pytest.approx(2.1, abs=0.05)
    grey = [int(g) for g in seen["grey"].split(",")]
    assert grey == pytest.approx([0, 60, 120, 180], abs=4)  # frames 0, 2, 4, 6


@needs_chromium
def test_killed_overlay_plays_in_a_browser(tmp_path: Path) -> None:
    target = tmp_path / "killed.mp4"
    killed_overlay(target, 35)
    seen = play_in_chromium(target, [0.05, 1.05, 2.95], tmp_path)
    assert seen.get("state") == "done", seen
    assert float(seen["duration"]) >= 3.0
    grey = [int(g) for g in seen["grey"].split(",")]
    assert grey == pytest.approx([0, 40, 116], abs=4)  # frames 0, 10, 29


def test_frame_times_before_zero_keep_their_spacing(tmp_path: Path) -> None:
    """Frame times from -1 s: every frame was put one millisecond after the previous one (the
    whole video played in a blink); the first frame is now at 0 and the spacing is kept."""
    for name, start in (("neg.mp4", -1.0), ("unix.mp4", 1_317_000_000.0)):  # and Unix times
        writer = OverlayWriter(tmp_path / name, fps=10.0)
        for k in range(4):
            writer.write(k, np.full((48, 64, 3), 50 * k, np.uint8), start + 0.1 * k)
        writer.close()
        assert decoded(tmp_path / name)[2] == pytest.approx([0.0, 0.1, 0.2, 0.3], abs=1e-6)
