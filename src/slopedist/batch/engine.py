"""The batch engine: many drives, one Ray task each, resumable, with a status table.

``run_batch`` plans (a drive whose folder is complete and whose input stamp is unchanged is
skipped), starts Ray (an embedded local instance on this machine's cores, or the cluster at
``address`` / ``$RAY_ADDRESS``), submits one task per remaining drive
(:func:`~slopedist.batch.drive.process_drive`, retried by Ray when its worker process dies),
collects outcomes as they finish (a progress bar over drives with the overall frames/s) and
writes ``OUT/status.csv`` and, with pyarrow, the fleet Parquet dataset. The engine is not a
scheduler: placement, retries and the cluster are Ray's. :func:`map_tasks` runs other
per-sequence work (``eval kitti-tracking --workers N``) on the same engine.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import signal
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

from tqdm import tqdm

from slopedist.batch.drive import (
    ATTEMPTS_PREFIX,
    CRASH_ENV,
    TMP_PREFIX,
    attempts_of,
    completed_stamp,
    error_text,
    process_drive,
)
from slopedist.batch.fleet import (
    DATASET_NAME,
    FLEET_NAMES,
    remove_partition,
    write_fleet_summary,
    write_partition,
)
from slopedist.batch.manifest import DriveSpec
from slopedist.batch.stamp import input_stamp
from slopedist.batch.status import STATUS_NAME, DriveOutcome, DriveStatus, write_status
from slopedist.core.errors import ConfigurationError, SlopedistError, import_optional
from slopedist.io.prefetch import usable_cores
from slopedist.streaming.loop import SUMMARY_NAME

T = TypeVar("T")

LOCK_NAME = ".lock"
"""File in ``OUT`` that a running batch holds (:func:`output_lock`)."""

DEFAULT_MAX_RETRIES = 2
"""Ray retries of a drive whose worker process died (not of a drive that failed on its data)."""


@dataclass(frozen=True)
class BatchOptions:
    """How to run a batch.

    Attributes:
        workers: CPUs of the embedded Ray instance (None: the cores this process may use,
            :func:`~slopedist.io.prefetch.usable_cores`); not with ``address``.
        address: Ray cluster to use (None: ``$RAY_ADDRESS`` if set, else an embedded instance).
        fail_fast: cancel the remaining drives at the first failure.
        force: run every drive, complete or not.
        max_retries: Ray retries of a task whose worker died.
        progress: show a progress bar over drives on stderr.
        parquet: write the fleet Parquet dataset (needs pyarrow).
    """

    workers: int | None = None
    address: str | None = None
    fail_fast: bool = False
    force: bool = False
    max_retries: int = DEFAULT_MAX_RETRIES
    progress: bool = True
    parquet: bool = True


@dataclass
class BatchResult:
    """What a batch did: one outcome per drive (manifest order) and totals.

    ``elapsed_s`` is the wall time (seconds) of the drives that ran; ``frames_per_s`` their
    frames over it.
    """

    out_dir: Path
    outcomes: list[DriveOutcome]
    elapsed_s: float = 0.0
    dataset: Path | None = None
    counts: dict[str, int] = field(default_factory=dict)

    @property
    def frames_run(self) -> int:
        return sum(o.frames for o in self.outcomes if o.status is DriveStatus.DONE)

    @property
    def frames_per_s(self) -> float:
        return self.frames_run / self.elapsed_s if self.elapsed_s > 0 else float("nan")

    def count(self, status: DriveStatus) -> int:
        return sum(o.status is status for o in self.outcomes)

    @property
    def all_failed(self) -> bool:
        """Every drive failed (none done, skipped or cancelled)."""
        return bool(self.outcomes) and self.count(DriveStatus.FAILED) == len(self.outcomes)


def import_ray(purpose: str = "slopedist batch") -> Any:
    """The ``ray`` module, or an :class:`OptionalDependencyError` saying how to install it
    (and what ``purpose`` needed it)."""
    return import_optional("ray", "batch", purpose)


@contextmanager
def ray_session(
    workers: int | None, address: str | None, purpose: str = "slopedist batch"
) -> Iterator[Any]:
    """Ray, initialised for the batch: the running instance if this process has one, else the
    cluster at ``address`` / ``$RAY_ADDRESS``, else an embedded instance with ``workers`` CPUs
    (when None, the cores this process may use: :func:`~slopedist.io.prefetch.usable_cores`,
    so a container's or ``taskset``'s CPU limit holds), shut down again at the end."""
    ray = import_ray(purpose)
    if ray.is_initialized():
        yield ray
        return
    address = address or os.environ.get("RAY_ADDRESS") or None
    if address and workers is not None:
        raise ConfigurationError(
            "--workers sizes the embedded Ray instance; on a cluster (--address or "
            "RAY_ADDRESS) the cluster's CPUs are used"
        )
    settings: dict[str, Any] = {
        "include_dashboard": False,
        "log_to_driver": False,
        "logging_level": logging.WARNING,
    }
    with kept_signal_handlers():
        if address:
            ray.init(address=address, **settings)
        else:
            # "local": a new instance even when an earlier `ray start` left its address behind
            ray.init(address="local", num_cpus=workers or usable_cores(), **settings)
        try:
            yield ray
        finally:
            ray.shutdown()


@contextmanager
def kept_signal_handlers() -> Iterator[None]:
    """Restore this process's SIGINT/SIGTERM handlers on exit (``ray.init`` installs its own
    and ``ray.shutdown`` leaves them)."""
    saved = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        if threading.current_thread() is threading.main_thread():
            for sig, handler in saved.items():
                signal.signal(sig, handler)


def map_tasks(
    fn: Callable[..., T],
    calls: Sequence[tuple[Any, ...]],
    workers: int,
    purpose: str,
    on_submit: Callable[[int], None] | None = None,
) -> list[T]:
    """``[fn(*args) for args in calls]``, one Ray task per call on an embedded instance with
    ``workers`` CPUs (or the running one), in the order of ``calls``; ``on_submit(i)`` as
    call ``i`` is submitted. ``fn`` must be a module-level function (workers import it).

    Raises:
        OptionalDependencyError: Ray is not installed (the message names ``purpose``).
        SlopedistError: the first call (in order) that raised one, re-raised as such.
    """
    with ray_session(workers, None, purpose) as ray:
        task = ray.remote(num_cpus=1, max_retries=DEFAULT_MAX_RETRIES)(fn)
        refs = []
        for i, args in enumerate(calls):
            if on_submit is not None:
                on_submit(i)
            refs.append(task.remote(*args))
        try:
            return list(ray.get(refs))
        except ray.exceptions.RayTaskError as exc:
            cause = getattr(exc, "cause", None)
            if isinstance(cause, SlopedistError):
                raise cause from None
            raise


def plan(
    drives: Sequence[DriveSpec], out_dir: Path, force: bool
) -> tuple[list[tuple[DriveSpec, dict[str, Any]]], dict[str, DriveOutcome]]:
    """Split the drives into those to run (with their input stamps) and the skipped ones
    (complete with an unchanged stamp)."""
    reserved = [d.name for d in drives if d.name in FLEET_NAMES]
    if reserved:
        raise ConfigurationError(f"drive name '{reserved[0]}' is reserved for a batch output")
    todo, skipped = [], {}
    for spec in drives:
        stamp = input_stamp(spec)
        folder = out_dir / spec.name
        if not force and completed_stamp(folder) == stamp:
            summary = json.loads((folder / SUMMARY_NAME).read_text(encoding="utf-8"))
            skipped[spec.name] = DriveOutcome(
                spec.name,
                DriveStatus.SKIPPED,
                frames=int(summary.get("frames") or 0),
                records=int(summary.get("records") or 0),
            )
        else:
            todo.append((spec, stamp))
    return todo, skipped


def check_outputs_spare_drive_inputs(drives: Sequence[DriveSpec], out_dir: Path) -> None:
    """Refuse a batch whose outputs would replace an input of one of its drives: a drive's
    folder ``OUT/<drive>`` (replaced whole when the drive runs, removed when it fails) or a
    fleet output (``status.csv``, ``fleet/``, ``records.parquet/``) that is, or holds, an
    input (frames, calibration, boxes, timestamps, depth maps, detector) of any drive, as
    ``--out`` set to the folder of the drives would; and an ``OUT`` inside a drive's frame or
    depth folder (its files would change that drive's input stamp).

    Raises:
        ConfigurationError: names the output, the input and its drive.
    """
    outputs = [out_dir / d.name for d in drives] + [out_dir / n for n in sorted(FLEET_NAMES)]
    resolved = [(o, o.resolve()) for o in outputs]
    for spec in drives:
        paths = (spec.frames, spec.calib, spec.boxes, spec.timestamps, spec.depth_dir)
        for path in (p for p in (*paths, spec.detector) if p is not None):
            held = path.resolve()
            for output, folder in resolved:
                if held == folder or folder in held.parents:
                    raise ConfigurationError(
                        f"the output {output} holds the input {path} of drive '{spec.name}': "
                        "choose another output (--out), the input would be replaced"
                    )
    out_resolved = out_dir.resolve()
    for spec in drives:
        for folder in (p for p in (spec.frames, spec.depth_dir) if p is not None and p.is_dir()):
            if folder.resolve() in (out_resolved, *out_resolved.parents):
                raise ConfigurationError(
                    f"the output {out_dir} lies in the input folder {folder} of drive "
                    f"'{spec.name}': the batch's files would change the drive's inputs (and "
                    "it would run again on every resume); choose an output outside it (--out)"
                )


def clean_leftovers(out_dir: Path) -> None:
    """Remove the temporary folders of killed tasks (no task of this output may be running)."""
    for path in out_dir.glob(f"{TMP_PREFIX}*"):
        shutil.rmtree(path, ignore_errors=True)


def run_batch(
    drives: Sequence[DriveSpec], out_dir: str | Path, options: BatchOptions
) -> BatchResult:
    """Run ``drives`` into ``OUT/<drive>`` folders (see the module docstring).

    Raises:
        OptionalDependencyError: Ray (or, for ``parquet``, pyarrow) is not installed.
        ConfigurationError: ``workers`` together with a cluster address, a reserved drive name,
            an output that would replace an input (:func:`check_outputs_spare_drive_inputs`).
    """
    out = Path(out_dir)
    check_outputs_spare_drive_inputs(drives, out)  # before OUT is made, perhaps in an input
    out.mkdir(parents=True, exist_ok=True)
    if options.parquet:
        from slopedist.batch.fleet import import_pyarrow

        import_pyarrow()
    with output_lock(out):
        return _run_locked(drives, out, options)


@contextmanager
def output_lock(out: Path) -> Iterator[None]:
    """Hold ``OUT/.lock`` (an exclusive ``flock``, released when this process ends, however it
    ends) while a batch writes into ``OUT``: a second batch into the same ``OUT`` would remove
    the first's running drives as leftovers and delete or replace its outputs.

    Raises:
        ConfigurationError: another batch holds it.
    """
    try:
        import fcntl
    except ImportError:  # pragma: no cover (not on Windows: no lock there)
        yield
        return
    with (out / LOCK_NAME).open("a+", encoding="utf-8") as fh:
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            fh.seek(0)
            holder = fh.read().strip() or "?"
            raise ConfigurationError(
                f"another slopedist batch (process {holder}) is writing into {out}: wait for "
                "it to end or choose another output (--out)"
            ) from None
        fh.seek(0)
        fh.truncate()
        fh.write(f"{os.getpid()}\n")
        fh.flush()
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def _run_locked(drives: Sequence[DriveSpec], out: Path, options: BatchOptions) -> BatchResult:
    """:func:`run_batch` once ``OUT`` exists and is this batch's."""
    clean_leftovers(out)
    todo, done = plan(drives, out, options.force)
    start = time.perf_counter()
    if todo:
        with ray_session(options.workers, options.address) as ray:
            done.update(_run_tasks(ray, todo, out, options))
        clean_leftovers(out)  # of attempts whose worker died
    result = BatchResult(out, [done[d.name] for d in drives], time.perf_counter() - start)
    if options.parquet:
        for outcome in result.outcomes:
            if outcome.status in (DriveStatus.DONE, DriveStatus.SKIPPED):
                write_partition(out, outcome.drive, refresh=outcome.status is DriveStatus.DONE)
            elif outcome.status is DriveStatus.FAILED:
                remove_partition(out, outcome.drive)
        result.dataset = out / DATASET_NAME
    write_status(out, result.outcomes)
    write_fleet_summary(out)
    return result


def _run_tasks(
    ray: Any, todo: list[tuple[DriveSpec, dict[str, Any]]], out: Path, options: BatchOptions
) -> dict[str, DriveOutcome]:
    """Submit one task per drive and gather the outcomes as they come."""
    task = ray.remote(num_cpus=1, max_retries=options.max_retries)(process_drive)
    hook = os.environ.get(CRASH_ENV)
    refs = {}
    for spec, stamp in todo:
        (out / f"{ATTEMPTS_PREFIX}{spec.name}").unlink(missing_ok=True)
        refs[task.remote(spec, out.absolute(), stamp, hook)] = spec.name
    outcomes: dict[str, DriveOutcome] = {}
    frames, start = 0, time.perf_counter()
    bar = tqdm(total=len(refs), unit="drive", disable=not options.progress, desc="slopedist batch")
    pending = list(refs)
    while pending:
        ready, pending = ray.wait(pending, num_returns=1)
        name = refs[ready[0]]
        try:
            outcome = ray.get(ready[0])
        except ray.exceptions.RayError as exc:  # retries exhausted, or cancelled
            outcome = DriveOutcome(name, DriveStatus.FAILED, error=error_text(exc))
        outcome.attempts = max(outcome.attempts, attempts_of(out, name))
        (out / f"{ATTEMPTS_PREFIX}{name}").unlink(missing_ok=True)
        outcomes[name] = outcome
        frames += outcome.frames
        bar.set_postfix_str(f"{frames / (time.perf_counter() - start):.1f} frames/s")
        bar.update(1)
        if options.fail_fast and outcome.status is DriveStatus.FAILED and pending:
            _cancel(ray, pending, refs, outcomes, name)
            pending = []
    bar.close()
    return outcomes


def _cancel(
    ray: Any, pending: list[Any], refs: dict[Any, str], outcomes: dict[str, DriveOutcome], why: str
) -> None:
    for ref in pending:
        ray.cancel(ref, force=True)
        outcomes[refs[ref]] = DriveOutcome(
            refs[ref],
            DriveStatus.CANCELLED,
            error=f"not run: --fail-fast after drive '{why}' failed",
        )


__all__ = ["STATUS_NAME", "BatchOptions", "BatchResult", "map_tasks", "run_batch"]
