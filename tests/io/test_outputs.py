"""Crash-safe outputs: temporary names, whole batches on a full disk, the folder lock, a
complete earlier run kept, stop flags, inputs spared."""

from __future__ import annotations

import errno
import os
import signal
import socket
import subprocess
import sys
import threading
from pathlib import Path

import pytest

import slopedist
from slopedist.core.errors import ConfigurationError
from slopedist.io.formatting import CsvStreamWriter
from slopedist.io.outputs import (
    LOCK_NAME,
    OutputFiles,
    OutputFolder,
    OutputFolderBusyError,
    OutputWriteError,
    StopFlag,
    WholeRowsFile,
    check_outputs_spare_inputs,
    partial_path,
    stop_on_signals,
)

SRC = str(Path(slopedist.__file__).resolve().parents[1])


def test_partial_names_keep_the_suffix() -> None:
    assert partial_path(Path("a/records.csv")) == Path("a/records.partial.csv")
    assert partial_path(Path("a/overlay.mp4")) == Path("a/overlay.partial.mp4")
    assert partial_path(Path("a/overlay")) == Path("a/overlay.partial")


def test_a_failed_write_names_the_file_and_cuts_it_back_to_whole_rows(tmp_path: Path) -> None:
    files = OutputFiles(tmp_path, ["t.csv"])
    path = files.path("t.csv")
    with path.open("w") as fh, files.writing("t.csv"):
        fh.write("a,b\n1,2\n")
        fh.flush()  # as CsvStreamWriter does after every batch
    with (
        pytest.raises(OutputWriteError, match=r"t\.csv: No space left"),
        path.open("a") as fh,
        files.writing("t.csv"),
    ):
        fh.write("3,")
        fh.flush()
        raise OSError(28, "No space left on device")
    assert path.read_text() == "a,b\n1,2\n"
    files.promote("s.json")
    files.write_summary("s.json", {"rows": 1})
    assert (tmp_path / "t.csv").read_text() == "a,b\n1,2\n" and not path.exists()
    assert (tmp_path / "s.json").read_text().strip().startswith("{")


def test_the_reserved_summary_is_overwritten_whole(tmp_path: Path) -> None:
    files = OutputFiles(tmp_path, [])
    files.reserve("s.json", 100)
    files.write_summary("s.json", {"a": 1})
    assert (tmp_path / "s.json").read_text() == '{\n  "a": 1\n}\n'


def test_promote_replaces_a_previous_overlay_folder(tmp_path: Path) -> None:
    overlay = tmp_path / "overlay"
    overlay.mkdir()
    (overlay / "000009.png").write_bytes(b"old")
    partial_path(overlay).mkdir()
    (partial_path(overlay) / "000000.png").write_bytes(b"new")
    OutputFiles(tmp_path, [], [overlay]).promote("s.json")
    assert sorted(p.name for p in overlay.iterdir()) == ["000000.png"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["overlay"]


def test_first_signal_sets_the_flag_second_interrupts() -> None:
    flag = StopFlag()
    with stop_on_signals(flag):
        os.kill(os.getpid(), signal.SIGTERM)
        assert flag.signum == signal.SIGTERM
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGTERM)
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL


def test_outputs_that_are_inputs_are_refused(tmp_path: Path) -> None:
    (tmp_path / "b.csv").write_text("x")
    with pytest.raises(ConfigurationError, match="would be overwritten"):
        check_outputs_spare_inputs([tmp_path / "." / "b.csv"], [tmp_path / "b.csv", None])
    with pytest.raises(ConfigurationError, match="would be overwritten"):
        check_outputs_spare_inputs([], [tmp_path], tmp_path)
    check_outputs_spare_inputs([tmp_path / "c.csv", None], [tmp_path / "b.csv"], tmp_path / "o")


def test_an_output_that_is_a_hard_link_to_an_input_is_refused(tmp_path: Path) -> None:
    """`slopedist estimate --calib calib.txt ... --out link.txt`, link.txt a hard link of
    calib.txt: the records replaced the calibration."""
    calib = tmp_path / "calib.txt"
    calib.write_text("P2: 1 0 0 0 0 1 0 0 0 0 1 0\n")
    link = tmp_path / "link.txt"
    os.link(calib, link)
    with pytest.raises(ConfigurationError, match=r"link.txt is the input .*calib.txt"):
        check_outputs_spare_inputs([link], [tmp_path / "poses.txt", calib])
    (tmp_path / "copy.txt").write_text(calib.read_text())  # the same content is not the file
    check_outputs_spare_inputs([tmp_path / "copy.txt"], [calib])


def test_a_full_disk_leaves_whole_batches_and_no_nul_byte(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A disk that fills in the middle of a batch: the kernel writes what fits (a short write),
    then refuses (ENOSPC). The file keeps its whole batches; nothing held back in a buffer is
    written later (a buffered file cut back and then closed wrote it at the old offset, after a
    run of NUL bytes)."""
    path = tmp_path / "t.csv"
    stream = WholeRowsFile(path)
    free = [30]
    real_write = os.write

    def small_disk(fd: int, data: bytes) -> int:
        if fd != stream._fd:
            return real_write(fd, data)
        if free[0] <= 0:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        n = real_write(fd, bytes(data)[: free[0]])
        free[0] -= n
        return n

    monkeypatch.setattr(os, "write", small_disk)
    stream.write("a,b\n")
    stream.flush()
    stream.write("1,2\n3,4\n")
    stream.flush()
    stream.write("5,6\n" * 10)  # 40 bytes, 18 free
    with pytest.raises(OSError, match="No space left") as failed:
        stream.flush()
    assert failed.value.filename == str(path)
    stream.write("7,8\n")
    with pytest.raises(OSError, match="No space left"):  # the file stays at its last batch
        stream.flush()
    free[0] = 1000  # space again (another file removed): nothing written after the gap
    stream.close()
    assert path.read_bytes() == b"a,b\n1,2\n3,4\n"
    assert stream.size == 12


def _hold_lock_in_another_process(folder: Path) -> subprocess.Popen[str]:
    """A process that takes the lock of ``folder``, says so on stdout and holds it until its
    standard input closes."""
    code = (
        "import sys; from pathlib import Path; from slopedist.io.outputs import OutputFolder\n"
        "with OutputFolder(Path(sys.argv[1])).lock():\n"
        "    print('locked', flush=True); sys.stdin.read()\n"
    )
    env = {**os.environ, "PYTHONPATH": SRC}
    proc = subprocess.Popen(
        [sys.executable, "-c", code, str(folder)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        env=env,
    )
    assert proc.stdout is not None and proc.stdout.readline().strip() == "locked"
    return proc


def test_a_folder_locked_by_another_process_is_refused_with_its_pid(tmp_path: Path) -> None:
    out = tmp_path / "out"
    holder = _hold_lock_in_another_process(out)
    try:
        with pytest.raises(OutputFolderBusyError) as busy, OutputFolder(out).lock():
            pytest.fail("a second lock of the folder was given")
        assert str(out) in str(busy.value) and f"pid {holder.pid} on " in str(busy.value)
    finally:
        holder.communicate("", timeout=60)
    assert not (out / LOCK_NAME).exists()  # released, and removed
    with OutputFolder(out).lock():  # free again
        assert (out / LOCK_NAME).read_text().startswith(f"pid {os.getpid()} on ")


def test_the_lock_of_a_killed_process_is_taken_over_with_a_note(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    out = tmp_path / "out"
    holder = _hold_lock_in_another_process(out)
    holder.kill()  # no chance to remove its lock file: the lock itself ends with the process
    holder.wait(timeout=60)
    assert (out / LOCK_NAME).read_text().startswith(f"pid {holder.pid} on ")
    with caplog.at_level("WARNING", logger="slopedist.io.outputs"), OutputFolder(out).lock():
        pass
    assert [r.getMessage() for r in caplog.records] == [
        f"note: took over the lock of {out} left by pid {holder.pid} on {socket.gethostname()}, "
        "which ended without releasing it"
    ]
    assert sorted(out.iterdir()) == []


def test_the_lock_is_taken_again_by_its_thread_and_refused_to_another(tmp_path: Path) -> None:
    """A command locks its folder and the run it starts locks it again (same thread); two
    runs in two threads of one process do not share it."""
    out = tmp_path / "out"
    refused: list[BaseException] = []

    def second() -> None:
        try:
            with OutputFolder(out).lock():
                pass
        except OutputFolderBusyError as exc:
            refused.append(exc)

    with OutputFolder(out).lock(), OutputFolder(out).lock():
        thread = threading.Thread(target=second)
        thread.start()
        thread.join()
        assert (out / LOCK_NAME).exists()
    assert len(refused) == 1 and "this process, another thread" in str(refused[0])
    assert not out.exists()  # created by the lock and left empty: removed


def _finished_run(out: Path) -> dict[str, bytes]:
    """A complete run's files in ``out`` (as ``slopedist run`` leaves them); their bytes."""
    out.mkdir()
    files = {
        "records.csv": b"frame,distance_m\n0,10\n",
        "run.json": b'{"complete": true}\n',
    }
    for name, data in files.items():
        (out / name).write_bytes(data)
    return files


def test_a_stopped_run_keeps_a_complete_earlier_run_and_stays_partial_beside_it(
    tmp_path: Path,
) -> None:
    out = tmp_path / "out"
    earlier = _finished_run(out)
    files = OutputFiles(out, ["records.csv"])
    files.reserve("run.json")
    with CsvStreamWriter(files.open_whole_rows("records.csv"), ["frame", "distance_m"]) as w:
        w.write_rows([{"frame": 0, "distance_m": 11.0}])
    files.close("records.csv", lambda: None)
    assert files.commit("run.json", complete=False) is False
    summary = files.write_summary("run.json", {"complete": False})
    assert summary == out / "run.partial.json"
    assert {n: (out / n).read_bytes() for n in earlier} == earlier
    assert (out / "records.partial.csv").read_text() == "frame,distance_m\n0,11\n"
    assert "complete earlier run" in files.kept_note() and files.where("records.csv") == (
        out / "records.partial.csv"
    )
    # a complete run replaces it, and so does a stopped run into a folder without one
    for complete, summary_text in ((True, b'{"complete": true}\n'), (False, b"{}")):
        again = OutputFiles(out, ["records.csv"])
        (out / "records.partial.csv").write_text("frame,distance_m\n0,12\n")
        (out / "run.json").write_bytes(summary_text)
        assert again.commit("run.json", complete=complete) is True
        assert (out / "records.csv").read_text() == "frame,distance_m\n0,12\n"


def test_outputs_with_nothing_whole_are_left_out(tmp_path: Path) -> None:
    """A table without even its header, a table written at once that failed, an extra
    output whose write failed: none takes its final name."""
    files = OutputFiles(tmp_path, ["a.csv", "t.csv", "b.csv"], whole_only=["t.csv"])
    files.open_whole_rows("a.csv")  # nothing written
    (tmp_path / "t.partial.csv").write_text("track_id\n1\n")  # (as far as it got)
    (tmp_path / "b.partial.csv").write_text("frame\n0\n")
    overlay = tmp_path / "overlay.mp4"
    files.add(overlay)
    partial_path(overlay).write_bytes(b"torn")

    def fail() -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    files.close("a.csv", lambda: None)
    files.close("t.csv", fail)
    with pytest.raises(OutputWriteError), files.writing(partial_path(overlay).name):
        fail()
    files.commit("s.json", complete=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.csv"]
    assert "t.csv: No space left" in files.failed
