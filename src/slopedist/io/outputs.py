"""Crash-safe outputs: files written whole or not at all, a lock on an output folder, temporary
names renamed only when a run may replace what the folder holds, stop requests from signals,
and the check that outputs spare the inputs.

- **Whole rows.** A table is written through a :class:`WholeRowsFile`: each batch of rows (one
  frame) goes to disk in unbuffered writes when it is complete, and a write that fails (a full
  disk) cuts the file back to the end of the last whole batch; nothing is left in a buffer to
  be flushed later, so the file never holds a torn row or a run of NUL bytes.
- **Temporary names.** A long-running command (``slopedist run``) writes each output under a
  temporary name (:func:`partial_path`: ``records.partial.csv``) and gives it its final name at
  the end (:meth:`OutputFiles.commit`): a complete run always does; a run that stopped early
  (a signal, an error, a full disk) does only when the folder holds no complete earlier run.
  Otherwise the complete earlier run stays as it is and the stopped run's files keep their
  temporary names beside it, with its summary as ``run.partial.json``. An output with nothing
  whole in it (not even its header) is removed rather than given its name.
- **A lock.** :meth:`OutputFolder.lock` takes an exclusive lock on the folder (``fcntl.flock`` on
  ``.slopedist.lock`` in it, which names the holder); a second command into the same folder is
  refused with :class:`OutputFolderBusyError`, naming the folder and the holder's pid. The lock
  ends with its process, however that ends: the file a killed process leaves is taken over,
  with a note. :func:`output_file_lock` does the same for a command that writes one file.
"""

from __future__ import annotations

import contextlib
import errno
import json
import logging
import os
import shutil
import signal
import socket
import threading
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from io import TextIOBase
from pathlib import Path
from types import FrameType
from typing import Any

from slopedist.core.errors import ConfigurationError, SlopedistError
from slopedist.core.paths import PATH_BYTES_ERRORS
from slopedist.io.formatting import dumps_json

try:
    import fcntl
except ImportError:  # pragma: no cover (Windows: the lock file is created exclusively)
    fcntl = None  # type: ignore[assignment]

_log = logging.getLogger(__name__)

PARTIAL_TAG = ".partial"
"""Inserted before the suffix of a file being written (``records.partial.csv``)."""

LOCK_NAME = ".slopedist.lock"
"""The lock file of an output folder (:meth:`OutputFolder.lock`); removed when the lock ends."""

SUMMARY_RESERVE_BYTES = 16384
"""Disk space taken for the summary JSON when a run starts (:meth:`OutputFiles.reserve`)."""

_OPEN_FLAGS = os.O_WRONLY | os.O_CREAT | getattr(os, "O_CLOEXEC", 0) | getattr(os, "O_BINARY", 0)


def partial_path(path: Path) -> Path:
    """The temporary name of an output while it is written (``a/records.partial.csv``)."""
    return path.with_name(f"{path.stem}{PARTIAL_TAG}{path.suffix}")


class OutputWriteError(SlopedistError):
    """Writing an output file failed (e.g. a full disk)."""

    def __init__(self, path: Path, exc: OSError) -> None:
        self.path = path
        super().__init__(f"cannot write {path}: {exc.strerror or exc}")


class OutputFolderBusyError(SlopedistError):
    """Another command holds the lock on an output folder (or file)."""

    def __init__(self, target: Path, holder: str) -> None:
        self.target = target
        super().__init__(
            f"{target} is in use by another slopedist command ({holder}): wait until it ends "
            "or choose another output; two commands writing one output would mix their files"
        )


def _write_all(fd: int, data: bytes) -> None:
    """Write every byte of ``data`` to ``fd`` (a short write, as a filling disk gives, is
    followed by another; the error of the one that fails is raised)."""
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view) :]


class WholeRowsFile(TextIOBase):
    """A UTF-8 text file that holds whole batches only: :meth:`write` collects text, :meth:`flush`
    writes the batch to disk unbuffered (``CsvStreamWriter`` flushes after every batch of rows).

    A failed write (a full disk) cuts the file back to the end of the last whole batch and makes
    every later write fail the same way: no torn row stays on disk and no buffer is written
    later at another offset (what leaves NUL bytes in a file). :attr:`size` is the length of the
    whole batches, bytes. Text is encoded with :data:`~slopedist.core.paths.PATH_BYTES_ERRORS`,
    so that a path of any bytes can be written into it.
    """

    def __init__(self, path: Path) -> None:
        super().__init__()
        self.path = path
        self._fd = os.open(path, _OPEN_FLAGS | os.O_TRUNC, 0o666)
        self._pending: list[str] = []
        self.size = 0
        self.error: OSError | None = None

    def writable(self) -> bool:
        return True

    def write(self, text: str) -> int:
        """Add ``text`` to the current batch (nothing reaches the disk before :meth:`flush`)."""
        self._pending.append(text)
        return len(text)

    def flush(self) -> None:
        """Write the current batch whole, or cut the file back to the last whole one and raise
        the error (``OSError``, e.g. ``ENOSPC``)."""
        if self.closed or not self._pending:
            return
        data = "".join(self._pending).encode("utf-8", PATH_BYTES_ERRORS)
        self._pending.clear()
        if self.error is not None:  # the file stopped at its last whole batch
            raise OSError(self.error.errno, self.error.strerror, str(self.path))
        try:
            _write_all(self._fd, data)
        except OSError as exc:
            self.error = exc
            with suppress(OSError):
                os.ftruncate(self._fd, self.size)
                os.lseek(self._fd, self.size, os.SEEK_SET)
            raise OSError(exc.errno, exc.strerror, str(self.path)) from exc
        self.size += len(data)

    def close(self, sync: bool = True) -> None:
        """Write the last batch, put the file on the disk (``fsync``, unless ``sync`` is false)
        and close it; it is closed even when that fails."""
        if self.closed:
            return
        try:
            self.flush()
            if sync and self.error is None:
                os.fsync(self._fd)
        finally:
            os.close(self._fd)
            super().close()


def write_file_whole(path: Path, data: bytes) -> None:
    """Write ``path`` with ``data`` whole, or not at all: a failed write (a full disk) removes
    the file and raises :class:`OutputWriteError` naming it."""
    try:
        fd = os.open(path, _OPEN_FLAGS | os.O_TRUNC, 0o666)
    except OSError as exc:
        raise OutputWriteError(path, exc) from exc
    try:
        _write_all(fd, data)
    except OSError as exc:
        os.close(fd)
        with suppress(OSError):
            os.unlink(path)
        raise OutputWriteError(path, exc) from exc
    os.close(fd)


def write_image(path: Path, image: Any, params: Iterable[int] = ()) -> None:
    """Encode ``image`` (BGR) in the format of ``path``'s suffix (OpenCV's encoders, as
    ``cv2.imwrite`` uses them) and write it whole (:func:`write_file_whole`); works for a path
    of any bytes, which ``cv2.imwrite`` does not take.

    Raises:
        OutputWriteError: the image cannot be encoded or written.
    """
    import cv2

    ok, data = cv2.imencode(path.suffix or ".png", image, list(params))
    if not ok:
        raise OutputWriteError(path, OSError(f"OpenCV could not encode {path.name}"))
    write_file_whole(path, data.tobytes())


@dataclass
class _HeldLock:
    """A lock this process holds: its file descriptor, the thread that took it and how many
    times that thread took it (a command and the run it starts both lock the folder)."""

    fd: int | None
    thread: int
    depth: int = 1


_HELD: dict[str, _HeldLock] = {}
_HELD_GUARD = threading.Lock()


def _holder() -> str:
    """How a lock file names its holder: ``pid 1234 on host``."""
    return f"pid {os.getpid()} on {socket.gethostname()}"


def _read_holder(fd: int) -> str:
    with suppress(OSError):
        return os.pread(fd, 256, 0).decode("utf-8", "replace").strip()
    return ""


def _write_holder(fd: int) -> None:
    with suppress(OSError):  # a full disk: the lock holds all the same, its holder unnamed
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{_holder()}\n".encode(), 0)


def _is_same_file(fd: int, path: Path) -> bool:
    try:
        st = os.stat(path)
    except OSError:
        return False
    own = os.fstat(fd)
    return (own.st_dev, own.st_ino) == (st.st_dev, st.st_ino)


_NO_LOCKS_ERRNOS = {"ENOLCK", "EOPNOTSUPP", "ENOTSUP", "ENOSYS", "EINVAL"}
"""``flock`` errors of a file system without locks (some network shares)."""


def _lock_file(lock_path: Path, target: Path) -> int | None:
    """Take the lock of ``lock_path`` (created), or raise :class:`OutputFolderBusyError`; the
    file's descriptor, or None where the file system has no locks (then said in a note)."""
    if fcntl is None:  # pragma: no cover (not on Windows)
        return _create_lock_file(lock_path, target)
    while True:
        fd = os.open(lock_path, os.O_RDWR | os.O_CREAT | getattr(os, "O_CLOEXEC", 0), 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _read_holder(fd) or "its pid not yet written"
            os.close(fd)
            raise OutputFolderBusyError(target, holder) from None
        except OSError as exc:
            os.close(fd)
            if errno.errorcode.get(exc.errno or 0, "") not in _NO_LOCKS_ERRNOS:
                raise
            _log.warning(
                f"note: {target} cannot be locked ({exc.strerror}): nothing stops another "
                "command from writing into it at the same time"
            )
            return None
        if _is_same_file(fd, lock_path):
            break
        os.close(fd)  # its holder removed it while this process opened it: take the new one
    left = _read_holder(fd)
    if left:
        _log.warning(
            f"note: took over the lock of {target} left by {left}, which ended without releasing it"
        )
    _write_holder(fd)
    return fd


def _create_lock_file(lock_path: Path, target: Path) -> int:  # pragma: no cover (Windows)
    """The lock without ``fcntl``: the lock file created exclusively (a file a killed command
    left is not taken over: the message names it)."""
    try:
        fd = os.open(lock_path, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o644)
    except FileExistsError:
        holder = lock_path.read_text(encoding="utf-8", errors="replace").strip() or "unknown"
        raise OutputFolderBusyError(
            target, f"{holder}; if no command runs, remove {lock_path}"
        ) from None
    _write_holder(fd)
    return fd


def _unlock_file(lock_path: Path, fd: int | None) -> None:
    """End a lock taken by :func:`_lock_file`: the file is removed, then unlocked."""
    if fd is None:
        return
    if fcntl is None:  # pragma: no cover (Windows: an open file cannot be removed)
        os.close(fd)
        with suppress(OSError):
            os.unlink(lock_path)
        return
    with suppress(OSError):
        os.unlink(lock_path)
    os.close(fd)


@contextmanager
def _exclusive(lock_path: Path, target: Path) -> Iterator[None]:
    """Hold the lock of ``lock_path`` on ``target`` inside the block; the thread that holds it
    may take it again (nested), another thread or process is refused."""
    key = os.path.realpath(lock_path)
    with _HELD_GUARD:
        held = _HELD.get(key)
        if held is not None and held.thread != threading.get_ident():
            raise OutputFolderBusyError(target, f"{_holder()}: this process, another thread")
        if held is not None:
            held.depth += 1
    if held is None:
        held = _HeldLock(_lock_file(lock_path, target), threading.get_ident())
        with _HELD_GUARD:
            _HELD[key] = held
    try:
        yield
    finally:
        with _HELD_GUARD:
            held.depth -= 1
            last = held.depth == 0
            if last:
                del _HELD[key]
        if last:
            _unlock_file(lock_path, held.fd)


def output_file_lock(path: Path) -> contextlib.AbstractContextManager[None]:
    """An exclusive lock on an output file (``slopedist estimate --out``): the lock file
    ``.NAME.lock`` beside it, as for a folder (:meth:`OutputFolder.lock`)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return _exclusive(path.with_name(f".{path.name}.lock"), path)


@contextmanager
def output_file(path: Path) -> Iterator[WholeRowsFile]:
    """Write the output file ``path`` whole, under its lock (:func:`output_file_lock`): the
    block writes a :class:`WholeRowsFile` under the temporary name (:func:`partial_path`),
    which takes the name ``path`` when the block ends. On an error or a stop inside the block,
    ``path`` is left as it was and the whole rows written so far stay under the temporary name
    (said in a note; a file without any is removed)."""
    with output_file_lock(path):
        tmp = partial_path(path)
        stream = WholeRowsFile(tmp)
        try:
            yield stream
            stream.close()
        except BaseException:
            stream.close(sync=False)
            if stream.size:
                _log.warning(
                    f"note: {path} is left as it was; the rows written before the command "
                    f"stopped are in {tmp}"
                )
            else:
                tmp.unlink(missing_ok=True)
            raise
        os.replace(tmp, path)
        _sync_folder(path.parent)


class OutputFolder:
    """An output folder: its lock, tables written whole under temporary names, and whether it
    holds a complete run.

    Args:
        path: the folder (created by :meth:`lock`).
    """

    def __init__(self, path: Path) -> None:
        self.path = Path(path)

    @contextmanager
    def lock(self) -> Iterator[OutputFolder]:
        """Hold the folder's lock inside the block (the folder is created first).

        Folders the lock created are removed again at its end if they are still empty (a
        command refused before it wrote anything leaves nothing behind).

        Raises:
            OutputFolderBusyError: another command holds it (the message names the folder and
                the holder's pid); a lock file left by a command that ended without releasing
                it is taken over, with a note.
        """
        created = [p for p in (self.path, *self.path.parents) if not p.exists()]
        self.path.mkdir(parents=True, exist_ok=True)
        try:
            with _exclusive(self.path / LOCK_NAME, self.path):
                yield self
        finally:
            for folder in created:  # the deepest first
                try:
                    folder.rmdir()
                except OSError:  # not empty (or gone): the command wrote into it
                    break

    def open_whole_rows(self, name: str) -> WholeRowsFile:
        """A :class:`WholeRowsFile` for output ``name``, under its temporary name."""
        return WholeRowsFile(partial_path(self.path / name))

    def holds_complete_run(self, summary_name: str) -> bool:
        """Whether the folder's summary ``summary_name`` (``run.json``) says its run is
        complete (``"complete": true``); no summary, or one that cannot be read, is not."""
        try:
            summary = json.loads((self.path / summary_name).read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return False
        return isinstance(summary, dict) and summary.get("complete") is True


class OutputFiles:
    """The output files of one run in a folder, under their temporary names until
    :meth:`commit`.

    Args:
        out: the output folder.
        names: file names (in ``out``) written through :meth:`writing`, e.g. ``records.csv``.
        extra: further outputs (a file or a folder anywhere) renamed from their
            :func:`partial_path` at the end, e.g. an overlay (more with :meth:`add`).
        whole_only: those of ``names`` written at once at the end (``tracks.csv``): one that
            cannot be written whole is removed, not kept up to its last whole batch.
    """

    def __init__(
        self,
        out: Path,
        names: Iterable[str],
        extra: Iterable[Path] = (),
        whole_only: Iterable[str] = (),
    ) -> None:
        self.out = Path(out)
        self.folder = OutputFolder(self.out)
        self.names = tuple(names)
        self.extra = list(extra)
        self.whole_only = frozenset(whole_only)
        self.streams: dict[str, WholeRowsFile] = {}
        self.good_size: dict[str, int] = {}
        self.failed = ""
        self.torn: set[str] = set()
        """Outputs (names, or an extra's name or temporary name) whose write or close failed."""
        self.replaces: bool | None = None
        """Set by :meth:`commit`: whether the outputs took their final names."""

    def path(self, name: str) -> Path:
        """Where output ``name`` is written until :meth:`commit`."""
        return partial_path(self.out / name)

    def where(self, name: str) -> Path:
        """Where output ``name`` is once the run ends: its final name, or its temporary one
        when :meth:`commit` kept a complete earlier run."""
        return self.path(name) if self.replaces is False else self.out / name

    def add(self, final: Path) -> None:
        """One more output renamed from its :func:`partial_path` to ``final`` at the end (a
        snapshot)."""
        if final not in self.extra:
            self.extra.append(final)

    def open_whole_rows(self, name: str) -> WholeRowsFile:
        """Output ``name`` as a :class:`WholeRowsFile` (closed by :meth:`close`)."""
        stream = self.folder.open_whole_rows(name)
        self.streams[name] = stream
        return stream

    @contextmanager
    def writing(self, name: str) -> Iterator[None]:
        """Write (and flush) a batch of rows to output ``name``: an OSError becomes
        :class:`OutputWriteError` naming the file, which is cut back to its last whole batch."""
        try:
            yield
        except OSError as exc:
            self.torn.add(name)
            self._cut_back(name)
            raise OutputWriteError(self.out / name, exc) from exc
        stream = self.streams.get(name)
        if stream is not None:
            self.good_size[name] = stream.size
        elif name in self.names:
            self.good_size[name] = self.path(name).stat().st_size

    def _cut_back(self, name: str) -> None:
        """Cut a file written by other means than a :class:`WholeRowsFile` (which cuts itself
        back) to its last whole batch."""
        path = self.path(name)
        if name in self.streams or name not in self.names:
            return
        with suppress(OSError):
            if path.exists():
                os.truncate(path, self.good_size.get(name, 0))

    def close(self, name: str, closer: Callable[[], None]) -> None:
        """Close output ``name`` with ``closer`` (then its :class:`WholeRowsFile`, if any); a
        failure (a full disk) is kept in :attr:`failed` and the file cut back to its last whole
        batch."""
        try:
            closer()
            stream = self.streams.get(name)  # (the closer may have opened it)
            if stream is not None:
                stream.close()
        except OSError as exc:
            self.torn.add(name)
            self._cut_back(name)
            self.failed = self.failed or str(OutputWriteError(self.out / name, exc))
        finally:
            stream = self.streams.get(name)
            if stream is not None:
                stream.close(sync=False)

    def commit(self, summary_name: str, complete: bool) -> bool:
        """End the run's outputs: an output with nothing whole in it is removed, then the
        others take their final names (:meth:`promote`) when the run is ``complete`` or the
        folder holds no complete earlier run; otherwise they keep their temporary names beside
        that run, which stays as it is. Returns whether they took their final names
        (:attr:`replaces`; the summary follows them, :meth:`write_summary`)."""
        self.replaces = complete or not self.folder.holds_complete_run(summary_name)
        self._remove_unwhole()
        if self.replaces:
            self.promote(summary_name)
        return self.replaces

    def _remove_unwhole(self) -> None:
        """Remove the outputs that are not whole: a table with not even its header, one of
        :attr:`whole_only` or an extra output whose write or close failed."""
        for name in self.names:
            path = self.path(name)
            with suppress(OSError):
                if (name in self.torn and name in self.whole_only) or path.stat().st_size == 0:
                    path.unlink()
        for final in self.extra:
            if {final.name, partial_path(final).name} & self.torn:
                _remove_path(partial_path(final))

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
        _sync_folder(self.out)

    def kept_note(self) -> str:
        """What a message adds when :meth:`commit` kept a complete earlier run (else "")."""
        if self.replaces is not False:
            return ""
        return (
            f"; the complete earlier run in {self.out} is kept as it was, and this run's files "
            f"keep their temporary names ({PARTIAL_TAG}) beside it"
        )

    def reserve(self, summary_name: str, size: int = SUMMARY_RESERVE_BYTES) -> None:
        """Take the summary's disk space now, so that it can still be written on a full disk.

        Raises:
            OutputWriteError: not even that space is free.
        """
        write_file_whole(self.path(summary_name), b" " * size)

    def write_summary(self, summary_name: str, payload: Any) -> Path:
        """The summary JSON, written last over its reserved space (:meth:`reserve`), then
        given its final name if the outputs took theirs (:meth:`commit`). Returns where it is;
        a failed write (``OSError``) leaves no summary file of this run."""
        tmp = self.path(summary_name)
        data = dumps_json(payload).encode("utf-8")
        try:
            fd = os.open(tmp, _OPEN_FLAGS, 0o666)
            try:
                _write_all(fd, data)
                os.ftruncate(fd, len(data))
                os.fsync(fd)
            finally:
                os.close(fd)
        except OSError:
            tmp.unlink(missing_ok=True)
            raise
        if self.replaces is False:
            return tmp
        os.replace(tmp, self.out / summary_name)
        _sync_folder(self.out)
        return self.out / summary_name


def _sync_folder(folder: Path) -> None:
    """Put a folder's renames on the disk (where folders can be opened and synced)."""
    with suppress(OSError, AttributeError):
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _remove_path(path: Path) -> None:
    """Remove a file or a folder, if there."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


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
