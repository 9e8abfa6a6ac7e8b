"""Results as an MCAP file with Foxglove schemas, for Foxglove (and any MCAP reader).

Why MCAP + Foxglove rather than a Rerun recording (docs/viewers.md): the teams this serves
record drives as ROS 2 bags whose default storage *is* MCAP, and open them in Foxglove; an
MCAP export sits next to the drive log in the same tools, plays in sync with it, and is
written by the small pure-Python ``mcap`` package (about 0.3 MB; optional extra ``mcap``),
where the Rerun SDK is a 170 MB wheel with a file format that changes between versions.

Messages are JSON (``jsonschema`` schemas), one set per frame, log time = the frame's time
(``start_ns`` + timestamp; moved so that the first frame is at 0 when its time would be
negative):

- ``/slopedist/image`` — ``foxglove.CompressedImage`` (JPEG, frame id ``camera``), when images
  are embedded;
- ``/slopedist/annotations`` — ``foxglove.ImageAnnotations``: each box as a closed line in its
  track's colour (red without a distance to act on), and its label (``#track distance m``,
  ``<= bound m (reason)`` for an upper bound, or ``missing: reason``);
- ``/slopedist/frame`` — ``slopedist.Frame``: frame index, time (s), the image reference (file
  name or ``topic#index`` of the source), frame status, θ (degrees), and every target (track,
  box in pixels, distance in metres (the bound of an ``upper_bound``), status, reason) — the
  numbers, for plots and checks;
- ``/slopedist/gradient`` — ``slopedist.Gradient``: θ (degrees) and the lead distance (m), a
  series for Foxglove's Plot panel.

Convention: boxes ``(left, top, right, bottom)`` pixels of the source image; distances metres;
θ degrees; times nanoseconds in MCAP, seconds in the JSON bodies.
"""

from __future__ import annotations

import base64
import json
import math
from pathlib import Path
from typing import IO, Any

import cv2
import numpy as np
from numpy.typing import NDArray

from slopedist.core.errors import DataMismatchError, InputFileError, OptionalDependencyError
from slopedist.estimators.base import FrameEstimates
from slopedist.io.detections.boxes import BoxTable
from slopedist.io.formatting import json_ready
from slopedist.streaming.drawing import FIG3_MISSING, distance_label, track_colour

IMAGE_TOPIC = "/slopedist/image"
ANNOTATIONS_TOPIC = "/slopedist/annotations"
FRAME_TOPIC = "/slopedist/frame"
GRADIENT_TOPIC = "/slopedist/gradient"
EXPORT_JPEG_QUALITY = 85
MAX_LOG_TIME_NS = 2**63
"""Log times of the export lie in ``[0, 2⁶³)`` ns (MCAP's are unsigned 64-bit; Foxglove reads
them as signed)."""

_TIME = {
    "type": "object",
    "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}},
}
_COLOR = {
    "type": "object",
    "properties": {k: {"type": "number"} for k in ("r", "g", "b", "a")},
}
_POINT2 = {"type": "object", "properties": {"x": {"type": "number"}, "y": {"type": "number"}}}
SCHEMAS: dict[str, dict[str, Any]] = {
    "foxglove.CompressedImage": {
        "title": "foxglove.CompressedImage",
        "type": "object",
        "properties": {
            "timestamp": _TIME,
            "frame_id": {"type": "string"},
            "data": {"type": "string", "contentEncoding": "base64"},
            "format": {"type": "string"},
        },
    },
    "foxglove.ImageAnnotations": {
        "title": "foxglove.ImageAnnotations",
        "type": "object",
        "properties": {
            "circles": {"type": "array", "items": {"type": "object"}},
            "points": {
                "type": "array",
                "items": {
                    "type": "object",
                    "properties": {
                        "timestamp": _TIME,
                        "type": {"type": "integer"},
                        "points": {"type": "array", "items": _POINT2},
                        "outline_color": _COLOR,
                        "outline_colors": {"type": "array", "items": _COLOR},
                        "fill_color": _COLOR,
                        "thickness": {"type": "number"},
                    },
                },
            },
            "texts": {
                "type": "array",
                "items": {
                    "type": "object",
                    "properties": {
                        "timestamp": _TIME,
                        "position": _POINT2,
                        "text": {"type": "string"},
                        "font_size": {"type": "number"},
                        "text_color": _COLOR,
                        "background_color": _COLOR,
                    },
                },
            },
        },
    },
    "slopedist.Frame": {
        "title": "slopedist.Frame",
        "type": "object",
        "properties": {
            "frame": {"type": "integer"},
            "timestamp_s": {"type": "number"},
            "image": {"type": "string"},
            "status": {"type": "string"},
            "method": {"type": "string"},
            "theta_deg": {"type": ["number", "null"]},
            "targets": {"type": "array", "items": {"type": "object"}},
        },
    },
    "slopedist.Gradient": {
        "title": "slopedist.Gradient",
        "type": "object",
        "properties": {
            "theta_deg": {"type": ["number", "null"]},
            "lead_distance_m": {"type": ["number", "null"]},
        },
    },
}
"""JSON schemas by name (the Foxglove ones restricted to the fields written here)."""

_TOPICS = {
    IMAGE_TOPIC: "foxglove.CompressedImage",
    ANNOTATIONS_TOPIC: "foxglove.ImageAnnotations",
    FRAME_TOPIC: "slopedist.Frame",
    GRADIENT_TOPIC: "slopedist.Gradient",
}
LINE_LOOP = 2
"""``foxglove.PointsAnnotationType`` of a closed polyline."""


def _stamp(t_ns: int) -> dict[str, int]:
    return {"sec": t_ns // 1_000_000_000, "nsec": t_ns % 1_000_000_000}


def _colour(bgr: tuple[int, int, int]) -> dict[str, float]:
    return {"r": bgr[2] / 255, "g": bgr[1] / 255, "b": bgr[0] / 255, "a": 1.0}


def _number(x: float) -> float | None:
    return float(x) if math.isfinite(float(x)) else None


def frame_targets(boxes: BoxTable, estimates: FrameEstimates) -> list[dict[str, Any]]:
    """One dict per target: track id, box (pixels), distance (m, None if missing; the bound of
    an ``upper_bound`` row), status (``ok``, ``upper_bound`` or ``missing``) and reason."""
    return [
        {
            "track_id": int(boxes.track_id[i]),
            "box": [float(c) for c in boxes.boxes[i]],
            "distance_m": _number(estimates.distance_m[i]),
            "status": str(estimates.status[i]),
            "reason": str(estimates.reason[i]),
        }
        for i in range(len(boxes))
    ]


def target_label(target: dict[str, Any]) -> str:
    """A target's label as the overlay writes it
    (:func:`~slopedist.streaming.drawing.distance_label`): a
    target without a distance, or of another status than ``ok`` and ``upper_bound``, reads
    ``#track missing: reason`` (never a number for a distance that is withheld)."""
    z, status, reason = target["distance_m"], target["status"], target["reason"]
    if z is None or status not in ("ok", "upper_bound"):
        z, status, reason = math.nan, "missing", reason or "no distance"
    return distance_label(target["track_id"], z, status, reason)


def image_annotations(t_ns: int, targets: list[dict[str, Any]]) -> dict[str, Any]:
    """``foxglove.ImageAnnotations`` of the targets (boxes as closed lines, labels
    (:func:`target_label`); a box with a coordinate that is not finite has neither)."""
    points, texts = [], []
    for tg in targets:
        if not all(math.isfinite(c) for c in tg["box"]):
            continue  # nowhere to draw it: its reason is in the slopedist.Frame message
        left, top, right, bottom = tg["box"]
        ok = tg["status"] == "ok" and tg["distance_m"] is not None
        colour = _colour(track_colour(tg["track_id"]) if ok else FIG3_MISSING)
        corners = [(left, top), (right, top), (right, bottom), (left, bottom)]
        points.append(
            {
                "timestamp": _stamp(t_ns),
                "type": LINE_LOOP,
                "points": [{"x": x, "y": y} for x, y in corners],
                "outline_color": colour,
                "outline_colors": [],
                "fill_color": {"r": 0.0, "g": 0.0, "b": 0.0, "a": 0.0},
                "thickness": 2.0,
            }
        )
        text = target_label(tg)
        texts.append(
            {
                "timestamp": _stamp(t_ns),
                "position": {"x": right + 3, "y": top},
                "text": text,
                "font_size": 14.0,
                "text_color": colour,
                "background_color": {"r": 0.0, "g": 0.0, "b": 0.0, "a": 0.6},
            }
        )
    return {"circles": [], "points": points, "texts": texts}


class McapExportWriter:
    """Writes the export frame by frame (see the module docstring); close it to finish the file.

    Args:
        path: the ``.mcap`` file (overwritten).
        method: method name written with every frame.
        start_ns: log time of ``timestamp_s = 0`` (e.g. the drive log's first image stamp).
        embed_images: write each frame's image as JPEG (else only its reference).
    """

    def __init__(
        self, path: str | Path, method: str, start_ns: int = 0, embed_images: bool = True
    ) -> None:
        try:
            from mcap.writer import Writer
        except ImportError as exc:
            raise OptionalDependencyError("mcap", "mcap", "the MCAP export") from exc
        self.path = Path(path)
        self.method = method
        self.start_ns = int(start_ns)
        self.embed_images = embed_images
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._stream: IO[bytes] = self.path.open("wb")
        self._writer = Writer(self._stream)
        self._writer.start(profile="", library="slopedist")
        schema_ids = {
            name: self._writer.register_schema(
                name, "jsonschema", json.dumps(schema).encode("utf-8")
            )
            for name, schema in SCHEMAS.items()
        }
        self._channels = {
            topic: self._writer.register_channel(topic, "json", schema_ids[name])
            for topic, name in _TOPICS.items()
        }
        self._seq = 0
        self.frames = 0

    def _log_time(self, index: int, timestamp_s: float) -> int:
        """The log time (ns) of a frame time: ``start_ns`` + the time. MCAP log times are
        unsigned: when the first frame's would be negative (frame times before 0 and no log
        origin), the origin moves so that the first frame is at 0 (the JSON bodies keep the
        frame times); a later frame before it (times that do not increase) is put at 0."""
        ns = timestamp_s * 1e9
        if not math.isfinite(ns) or abs(ns) >= MAX_LOG_TIME_NS:
            raise DataMismatchError(
                f"frame {index}: time {timestamp_s} s is beyond the log times of an MCAP file "
                f"({MAX_LOG_TIME_NS / 1e9:.3g} s): frame times are seconds"
            )
        if self.frames == 0 and self.start_ns + round(ns) < 0:
            self.start_ns = -round(ns)
        t_ns = max(self.start_ns + round(ns), 0)
        if t_ns >= MAX_LOG_TIME_NS:
            raise DataMismatchError(
                f"frame {index}: log time {t_ns} ns is beyond those of an MCAP file "
                f"({MAX_LOG_TIME_NS} ns)"
            )
        return t_ns

    def _put(self, topic: str, t_ns: int, body: dict[str, Any]) -> None:
        data = json.dumps(json_ready(body), allow_nan=False).encode("utf-8")
        self._writer.add_message(self._channels[topic], t_ns, data, t_ns, self._seq)
        self._seq += 1

    def write_frame(
        self,
        index: int,
        timestamp_s: float,
        source: str,
        status: str,
        image: NDArray[np.uint8] | None,
        boxes: BoxTable,
        estimates: FrameEstimates,
        theta_rad: float,
        lead: int | None = None,
    ) -> None:
        """Write one frame (``image`` None for frames without pixels; ``lead`` the index of the
        lead vehicle among ``boxes``, if any).

        Raises:
            DataMismatchError: a frame time that is not finite or lies beyond the log times an
                MCAP file holds (0 to 2⁶³ ns, 292 years: a time in milliseconds or nanoseconds
                read as seconds).
        """
        t_ns = self._log_time(index, timestamp_s)
        targets = frame_targets(boxes, estimates)
        theta_deg = _number(math.degrees(theta_rad)) if math.isfinite(theta_rad) else None
        if image is not None and self.embed_images:
            ok, buf = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, EXPORT_JPEG_QUALITY])
            if not ok:
                raise InputFileError(self.path, f"frame {index}: image does not encode as JPEG")
            self._put(
                IMAGE_TOPIC,
                t_ns,
                {
                    "timestamp": _stamp(t_ns),
                    "frame_id": "camera",
                    "data": base64.b64encode(buf.tobytes()).decode("ascii"),
                    "format": "jpeg",
                },
            )
        self._put(ANNOTATIONS_TOPIC, t_ns, image_annotations(t_ns, targets))
        frame = {
            "frame": int(index),
            "timestamp_s": float(timestamp_s),
            "image": source,
            "status": status,
            "method": self.method,
            "theta_deg": theta_deg,
            "targets": targets,
        }
        self._put(FRAME_TOPIC, t_ns, frame)
        lead_m = targets[lead]["distance_m"] if lead is not None else None
        self._put(GRADIENT_TOPIC, t_ns, {"theta_deg": theta_deg, "lead_distance_m": lead_m})
        self.frames += 1

    def close(self) -> None:
        """Write the summary and close the file."""
        if self._stream.closed:
            return
        self._writer.finish()
        self._stream.close()


def read_mcap_export(path: str | Path) -> dict[str, list[tuple[int, dict[str, Any]]]]:
    """``{topic: [(log time ns, decoded JSON body), ...]}`` of an export (or any JSON MCAP)."""
    try:
        from mcap.reader import make_reader
    except ImportError as exc:
        raise OptionalDependencyError("mcap", "mcap", "reading an MCAP export") from exc
    out: dict[str, list[tuple[int, dict[str, Any]]]] = {}
    with Path(path).open("rb") as fh:
        for _, channel, message in make_reader(fh).iter_messages():
            out.setdefault(channel.topic, []).append(
                (int(message.log_time), json.loads(message.data))
            )
    return out
