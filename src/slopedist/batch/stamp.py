"""Input stamps: what a drive's outputs were made from, so that a re-run can skip it.

A stamp records, for every input path of a drive, its size and modification time, and for small
files (calibration, boxes, timestamps: up to :data:`HASH_LIMIT_BYTES`) a SHA-256 of the content;
for a folder (image frames, depth maps) the number of files, their total size and a SHA-256 of
the listing (name, size, mtime). The drive's options (:func:`~slopedist.batch.manifest.
spec_summary`; the run settings where they are not the defaults) are hashed too: a drive run
with other settings (reference point, ``ours`` options, offline mode, overlay, ...) runs
again. Two stamps are equal when nothing that could change the outputs
changed; touching a small file without changing it does not count as a change.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any

from slopedist.batch.manifest import DriveSpec, spec_summary

HASH_LIMIT_BYTES = 1 << 20
"""Files up to this size (1 MiB) are hashed; larger ones (videos) are stamped by size + mtime."""

STAMP_KEY = "batch_inputs"
"""Key of the stamp in the drive's ``run.json``."""

SETTINGS_KEY = "batch_drive"
"""Key of the drive's options (:func:`~slopedist.batch.manifest.spec_summary`: inputs, method,
camera and run settings) in its ``run.json``."""


def _sha256_file(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 16), b""):
            digest.update(chunk)
    return digest.hexdigest()


def path_stamp(path: Path) -> dict[str, Any]:
    """Stamp of one input file or folder (see the module docstring); a missing path is
    ``{"missing": True}``."""
    if path.is_file():
        st = path.stat()
        if st.st_size <= HASH_LIMIT_BYTES:
            return {"size": st.st_size, "sha256": _sha256_file(path)}
        return {"size": st.st_size, "mtime_ns": st.st_mtime_ns}
    if path.is_dir():
        digest = hashlib.sha256()
        count = total = 0
        with os.scandir(path) as entries:
            for entry in sorted(entries, key=lambda e: e.name):
                if entry.is_file():
                    st = entry.stat()
                    digest.update(f"{entry.name}\0{st.st_size}\0{st.st_mtime_ns}\n".encode())
                    count += 1
                    total += st.st_size
        return {"files": count, "size": total, "listing_sha256": digest.hexdigest()}
    return {"missing": True}


def input_stamp(spec: DriveSpec) -> dict[str, Any]:
    """Stamp of every input of ``spec`` and a hash of its options (JSON-ready)."""
    options = json.dumps(spec_summary(spec, changed_only=True), sort_keys=True)
    paths = {
        "frames": spec.frames,
        "calib": spec.calib,
        "boxes": spec.boxes,
        "timestamps": spec.timestamps,
        "depth_dir": spec.depth_dir,
        "detector": spec.detector,
    }
    return {
        "options_sha256": hashlib.sha256(options.encode()).hexdigest(),
        "inputs": {k: path_stamp(p) for k, p in paths.items() if p is not None},
    }
