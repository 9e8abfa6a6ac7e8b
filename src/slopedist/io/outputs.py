"""Crash-safe output files: temporary names renamed at the end, writes that name the file when
the disk is full, stop requests from signals, and the check that outputs spare the inputs.

A long-running command (``slopedist run``) writes each output under a temporary name
(:func:`partial_path`: ``records.partial.csv``) and gives it its final name only when it ends
(:meth:`OutputFiles.promote`), so that a previous result in the same folder stays whole until
the new one is finished, and a kill that leaves no chance to finish leaves the previous result
beside clearly marked ``.partial`` files. A failed write (a full disk) cuts the file back to
the end of its last whole batch of rows, so what stays on disk is valid CSV.
"""

from __future__ import annotations

import os
import shutil
import signal
import threading
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager, suppress
from pathlib import Path
from types import FrameType
from typing import Any

from slopedist.core.errors import ConfigurationError, SlopedistError
from slopedist.io.formatting import dumps_json

PARTIAL_TAG = ".partial"
"""Inserted before the suffix of a file being written (``records.partial.csv``)."""


SUMMARY_RESERVE_BYTES = 16384
"""Disk space taken for the summary JSON when a run starts (:meth:`OutputFiles.reserve`)."""


def partial_path(path: Path) -> Path:
    """The temporary name of an output while it is written (``a/records.partial.csv``)."""
    return path.with_name(f"{path.stem}{PARTIAL_TAG}{path.suffix}")


class OutputWriteError(SlopedistError):
    """Writing an output file failed (e.g. a full disk)."""

    def __init__(self, path: Path, exc: OSError) -> None:
        self.path = path
        super().__init__(f"cannot write {path}: {exc.strerror or exc}")


class RunStoppedError(SlopedistError):
    """A stop request (a signal) ended a loop between two frames."""

    def __init__(self, signum: int) -> None:
        self.signum = signum
        super().__init__(f"stopped by {signal.Signals(signum).name}")


class StopFlag:
    """A stop request for a running loop: :attr:`signum` is set by :func:`stop_on_signals`
    (or by hand); the loop checks it after every frame."""

    def __init__(self) -> None:
        self.signum: int | None = None


@contextmanager
def stop_on_signals(
    flag: StopFlag, signums: Iterable[int] = (signal.SIGTERM, signal.SIGINT)
) -> Iterator[StopFlag]:
    """While inside, the first of ``signums`` sets ``flag`` (the loop stops after its current
    frame and writes its summary); a second one raises :class:`KeyboardInterrupt` at once.
    Outside the main thread (no signal handlers there) nothing is installed."""
    if threading.current_thread() is not threading.main_thread():
        yield flag
        return

    def handler(signum: int, frame: FrameType | None) -> None:
        if flag.signum is not None:
            raise KeyboardInterrupt
        flag.signum = signum

    previous = {s: signal.signal(s, handler) for s in signums}
    try:
        yield flag
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


class OutputFiles:
    """Output files of one folder under their temporary names.

    Args:
        out: the output folder.
        names: file names (in ``out``) written through :meth:`writing`, e.g. ``records.csv``.
        extra: further outputs (a file or a folder anywhere) renamed from their
            :func:`partial_path` at the end, e.g. an overlay.
    """

    def __init__(self, out: Path, names: Iterable[str], extra: Iterable[Path] = ()) -> None:
        self.out = out
        self.names = tuple(names)
        self.extra = tuple(extra)
        self.good_size: dict[str, int] = {}
        self.failed = ""

    def path(self, name: str) -> Path:
        """Where output ``name`` is written until :meth:`promote`."""
        return partial_path(self.out / name)

    @contextmanager
    def writing(self, name: str) -> Iterator[None]:
        """Write (and flush) a batch of rows to output ``name``: an OSError becomes
        :class:`OutputWriteError` naming the file, which is cut back to its last whole batch."""
        try:
            yield
        except OSError as exc:
            self._cut_back(name)
            raise OutputWriteError(self.out / name, exc) from exc
        self.good_size[name] = self.path(name).stat().st_size

    def _cut_back(self, name: str) -> None:
        path = self.path(name)
        with suppress(OSError):
            if path.exists():
                os.truncate(path, self.good_size.get(name, 0))

    def close(self, name: str, closer: Callable[[], None]) -> None:
        """Close output ``name`` with ``closer``; a failure (a full disk) is kept in
        :attr:`failed` and the file cut back to its last whole batch."""
        try:
            closer()
        except OSError as exc:
            self._cut_back(name)
            self.failed = self.failed or str(OutputWriteError(self.out / name, exc))

    def promote(self, summary_name: str) -> None:
        """Give the outputs their final names, after removing the previous summary
        ``summary_name`` (so that it never stands beside other outputs)."""
        (self.out / summary_name).unlink(missing_ok=True)
        for name in self.names:
            if self.path(name).exists():
                os.replace(self.path(name), self.out / name)
        for final in self.extra:
            if partial_path(final).exists():
                _replace_path(partial_path(final), final)

    def reserve(self, summary_name: str, size: int = SUMMARY_RESERVE_BYTES) -> None:
        """Take the summary's disk space now, so that it can still be written on a full disk."""
        self.path(summary_name).write_bytes(b" " * size)

    def write_summary(self, summary_name: str, payload: Any) -> None:
        """The summary JSON, written last over its reserved space (:meth:`reserve`), then
        renamed to its final name."""
        tmp = self.path(summary_name)
        data = dumps_json(payload).encode("utf-8")
        with tmp.open("r+b" if tmp.exists() else "wb") as fh:
            fh.write(data)
            fh.truncate(len(data))
        os.replace(tmp, self.out / summary_name)


def _replace_path(new: Path, final: Path) -> None:
    """Move ``new`` (a file or folder) to ``final``, replacing what is there."""
    if new.is_dir() and final.exists():
        old = final.with_name(f"{final.name}.old")
        shutil.rmtree(old, ignore_errors=True)
        os.replace(final, old)
        os.replace(new, final)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.replace(new, final)


def check_outputs_spare_inputs(
    outputs: Iterable[Path | None], inputs: Iterable[Path | None], out_dir: Path | None = None
) -> None:
    """Refuse outputs that would overwrite an input (or an output folder that is an input).

    Raises:
        ConfigurationError: an output path is an input path, or ``out_dir`` is one.
    """
    ins = {Path(p).resolve(): Path(p) for p in inputs if p is not None}
    for o in [*outputs, out_dir]:
        if o is None:
            continue
        same = ins.get(Path(o).resolve()) or _same_file_among(Path(o), ins.values())
        if same is not None:
            raise ConfigurationError(
                f"the output {o} is the input {same}: choose another output "
                "(--out), the input would be overwritten"
            )


def _same_file_among(output: Path, inputs: Iterable[Path]) -> Path | None:
    """The input that is the existing file ``output`` under another name (a hard link), if any."""
    try:
        out = output.stat()
    except OSError:  # not there yet: no input to overwrite
        return None
    for p in inputs:
        try:
            st = p.stat()
        except OSError:
            continue
        if (st.st_dev, st.st_ino) == (out.st_dev, out.st_ino):
            return p
    return None
