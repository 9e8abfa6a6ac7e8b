"""One drive of a batch: run it into a temporary folder, stamp it, publish it atomically.

:func:`run_single_drive` is the one adapter between the batch engine and the single-drive
library: it runs :func:`slopedist.streaming.setup.run_to_folder`, the code ``slopedist run`` runs.
:func:`process_drive` is the task the engine runs per drive (in a Ray worker): it never raises
for a drive's own failure, it returns a failed :class:`~slopedist.batch.status.DriveOutcome`.

A drive's outputs appear in ``OUT/<drive>/`` by one rename of a complete folder, so a batch
killed at any moment leaves each drive either complete (with its input stamp and the options it
was run with in ``run.json``) or absent; temporary folders (``OUT/.tmp-*``) of killed tasks are
removed by the next batch.
"""

from __future__ import annotations

import functools
import json
import logging
import math
import os
import shutil
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, cast

from slopedist.batch.manifest import DriveSpec, spec_summary
from slopedist.batch.stamp import SETTINGS_KEY, STAMP_KEY
from slopedist.batch.status import DriveOutcome, DriveStatus
from slopedist.core.errors import SlopedistError
from slopedist.io.detections.onnx_detector import OnnxDetector
from slopedist.io.formatting import write_json
from slopedist.io.frames import Frame, FrameSource
from slopedist.io.prefetch import opencv_threads
from slopedist.streaming.config import SUMMARY_NAME, RunResult
from slopedist.streaming.setup import (
    LogTopicNames,
    RunOptions,
    folder_depth_source,
    run_to_folder,
)
from slopedist.streaming.step import RecordColumns

TMP_PREFIX = ".tmp-"
ATTEMPTS_PREFIX = ".attempts-"
CRASH_ENV = "SLOPEDIST_BATCH_TEST_CRASH"
"""Test hook: ``DRIVE:N`` makes the first attempt of drive ``DRIVE`` end its process
(``os._exit``) after ``N`` frames, as a worker killed mid-drive would."""


def drive_options(spec: DriveSpec, out_dir: Path) -> RunOptions:
    """The :class:`~slopedist.streaming.setup.RunOptions` of ``slopedist run`` with the options
    of ``spec`` into ``out_dir`` (the detector with its default settings; estimator defaults but
    the method, its offline mode, the reference point and the ``ours`` options of
    ``spec.settings``; its overlay, exports and vehicle classes), with no progress bar and
    frames decoded in the loop (``decode_ahead=0``, see :func:`run_single_drive`)."""
    detector = spec.detector
    settings = spec.settings
    return RunOptions(
        spec.frames,
        out_dir,
        spec.calib,
        boxes=spec.boxes,
        score=spec.score,
        detector=functools.partial(OnnxDetector, detector) if detector is not None else None,
        fps=spec.fps,
        timestamps=spec.timestamps,
        topics=LogTopicNames(spec.image_topic, spec.rotation_topic, spec.speed_topic),
        height_m=spec.height_m,
        mount_angle_deg=spec.mount_angle_deg,
        odometry=spec.odometry,
        lookback_s=spec.lookback_s,
        estimator=settings.estimator(spec.method),
        depth=functools.partial(folder_depth_source, spec.depth_dir) if spec.depth_dir else None,
        overlay=settings.overlay,
        overlay_format=settings.overlay_format,
        exports=tuple(settings.export),
        progress=False,
        sequence=spec.sequence or spec.name,
        vehicle_classes=settings.vehicle_classes,
        reference=settings.shown_reference(),
        decode_ahead=0,
        columns=RecordColumns(settings.columns),
    )


def run_single_drive(spec: DriveSpec, out_dir: Path, crash_after: int | None = None) -> RunResult:
    """Run ``spec`` into ``out_dir`` as ``slopedist run`` does with the same options (both
    through :func:`~slopedist.streaming.setup.run_to_folder`); ``crash_after`` is the test hook
    of :data:`CRASH_ENV`.

    Raises:
        SlopedistError / OSError: bad inputs or options, as ``slopedist run`` raises them.
    """
    wrap = None
    if crash_after is not None:
        wrap = functools.partial(_crashing_frames, after=crash_after)
    # a drive task holds one CPU (num_cpus=1) and decodes in its loop (decode_ahead=0): more
    # OpenCV threads would only compete with the other workers on the node, at a higher CPU
    # cost per frame; a batch scales by running one drive per core
    with opencv_threads(1):
        return run_to_folder(drive_options(spec, out_dir), wrap_frames=wrap)


def _crashing_frames(inner: FrameSource, after: int) -> FrameSource:
    return cast(FrameSource, _CrashingFrames(inner, after))


class _CrashingFrames:
    """A frame source that ends the process after ``after`` frames (test hook)."""

    def __init__(self, inner: FrameSource, after: int) -> None:
        self._inner = inner
        self._after = after

    def __getattr__(self, name: str) -> Any:
        return getattr(self._inner, name)

    def __iter__(self) -> Iterator[Frame]:
        for i, frame in enumerate(self._inner):
            if i == self._after:
                os._exit(17)
            yield frame


def count_attempt(out_root: Path, drive: str) -> int:
    """Record one more attempt of ``drive`` (a line in ``OUT/.attempts-<drive>``); returns the
    attempt number, 1 for the first."""
    path = out_root / f"{ATTEMPTS_PREFIX}{drive}"
    with path.open("a", encoding="utf-8") as fh:
        fh.write(f"{os.getpid()}\n")
    return len(path.read_text(encoding="utf-8").splitlines())


def attempts_of(out_root: Path, drive: str) -> int:
    """How many attempts of ``drive`` :func:`count_attempt` recorded (0 when none)."""
    path = out_root / f"{ATTEMPTS_PREFIX}{drive}"
    return len(path.read_text(encoding="utf-8").splitlines()) if path.is_file() else 0


def _crash_after(drive: str, attempt: int, hook: str | None) -> int | None:
    if not hook or attempt != 1:
        return None
    name, _, after = hook.rpartition(":")
    return int(after) if name == drive else None


def publish(tmp: Path, final: Path) -> None:
    """Move the complete folder ``tmp`` to ``final``, replacing an older ``final``; between
    the two renames a reader sees no ``final`` rather than a mixed one."""
    if final.exists():
        old = final.with_name(f"{TMP_PREFIX}old-{final.name}-{uuid.uuid4().hex[:8]}")
        final.rename(old)
        tmp.rename(final)
        shutil.rmtree(old, ignore_errors=True)
    else:
        tmp.rename(final)


def relocated(summary: dict[str, Any], tmp: Path, final: Path) -> dict[str, Any]:
    """``run.json`` of a run into ``tmp`` with its paths (``out_dir``, the overlay, the
    exports) pointing into ``final``, where the folder is published."""

    def move(value: Any) -> Any:
        if isinstance(value, list):
            return [move(v) for v in value]
        if isinstance(value, str) and (value == str(tmp) or value.startswith(f"{tmp}{os.sep}")):
            return str(final) + value[len(str(tmp)) :]
        return value

    return {k: move(v) for k, v in summary.items()}


def error_text(exc: BaseException) -> str:
    """One line for ``status.csv``: the message of a slopedist error, else type and message."""
    text = str(exc) if isinstance(exc, SlopedistError) else f"{type(exc).__name__}: {exc}"
    return " ".join(text.split())


def process_drive(
    spec: DriveSpec, out_root: Path, stamp: dict[str, Any], crash_hook: str | None = None
) -> DriveOutcome:
    """Run one drive into ``OUT/<drive>`` atomically and return its outcome (never raises for
    the drive's own errors: a corrupt drive fails alone). ``stamp`` goes into ``run.json``."""
    attempt = count_attempt(out_root, spec.name)
    tmp = out_root / f"{TMP_PREFIX}{spec.name}-{uuid.uuid4().hex[:8]}"
    final = out_root / spec.name
    start, cpu_start = time.perf_counter(), time.process_time()
    warnings: list[str] = []  # kept for a failed drive too: a dropped-rows line may explain it
    try:
        with logged_warnings(warnings):
            result = run_single_drive(spec, tmp, _crash_after(spec.name, attempt, crash_hook))
        summary_path = tmp / SUMMARY_NAME
        summary = relocated(json.loads(summary_path.read_text(encoding="utf-8")), tmp, final)
        summary[STAMP_KEY] = stamp
        summary[SETTINGS_KEY] = spec_summary(spec)
        write_json(summary_path, summary)
        publish(tmp, final)
    except Exception as exc:  # failure isolation: any error of this drive is its own
        shutil.rmtree(tmp, ignore_errors=True)
        shutil.rmtree(final, ignore_errors=True)  # outputs of older inputs are stale now
        return DriveOutcome(
            spec.name,
            DriveStatus.FAILED,
            error=error_text(exc),
            seconds=time.perf_counter() - start,
            attempts=attempt,
            warnings=tuple(warnings),
        )
    return DriveOutcome(
        spec.name,
        DriveStatus.DONE,
        frames=result.frames,
        records=result.records,
        seconds=time.perf_counter() - start,
        cpu_seconds=time.process_time() - cpu_start,
        attempts=attempt,
        worker_peak_rss_mb=peak_rss_mb(),
        warnings=tuple(warnings),
    )


class _WarningList(logging.Handler):
    """Keeps the messages of the warnings (and worse) logged to it in ``messages``."""

    def __init__(self, messages: list[str]) -> None:
        super().__init__(logging.WARNING)
        self.messages = messages

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())


@contextmanager
def logged_warnings(messages: list[str] | None = None) -> Iterator[list[str]]:
    """The messages of the warnings slopedist's loggers log inside the block (a drive's run in
    a Ray worker, whose own log reaches no one: :data:`~slopedist.batch.engine` starts Ray
    without ``log_to_driver``), e.g. the rows a box file's reader left out; appended to
    ``messages`` (None: a new list), which the block also gets, and kept when it raises."""
    handler = _WarningList([] if messages is None else messages)
    logger = logging.getLogger("slopedist")
    logger.addHandler(handler)
    try:
        yield handler.messages
    finally:
        logger.removeHandler(handler)


def peak_rss_mb() -> float:
    """Peak resident memory of this process so far, MB (NaN where ``resource`` is missing)."""
    try:
        import resource
    except ImportError:  # pragma: no cover (not on Windows)
        return math.nan
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # kB on Linux


def completed_stamp(folder: Path) -> dict[str, Any] | None:
    """The input stamp of a complete drive folder, or None (no folder, no or unreadable
    ``run.json``, a run that stopped on an error, or no stamp)."""
    path = folder / SUMMARY_NAME
    try:
        summary = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError):
        return None
    if not isinstance(summary, dict) or summary.get("error"):
        return None
    stamp = summary.get(STAMP_KEY)
    return stamp if isinstance(stamp, dict) else None
