"""Pre- and post-processing cost of the ONNX detector per frame, apart from the model itself.

A test-built model with the output of a real YOLOv8/YOLO11 COCO export — ``[1, 84, 8400]`` for a
640×640 input — whose graph does no work (a constant output: ~1 500 candidates scored 0.05–0.95,
the rest below 0.01, in clusters that NMS must reduce), so that the time outside inference is what
slopedist adds: letterbox + blob (``preprocess_ms``) and decoding, score threshold, class-aware
NMS, letterbox undo and class map (``postprocess_ms``). Frames are 1280×720 BGR. Timed in
process CPU time (``time.process_time``; the machine is shared, wall time is noisy) with OpenCV,
numpy and onnxruntime on one thread; the median and 95th percentile over the frames.

Usage::

    python benchmarks/detector_overhead.py [--frames 200] [--size 1280x720]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from slopedist.io.detections.onnx_detector import DetectorSettings, OnnxDetector  # noqa: E402


def yolov8_output(rng: np.random.Generator, n: int = 8400, classes: int = 80) -> np.ndarray:
    """``[1, 4 + classes, n]``: background candidates plus clusters around 60 objects."""
    out = np.zeros((4 + classes, n), np.float32)
    out[0] = rng.uniform(0, 640, n)
    out[1] = rng.uniform(140, 500, n)
    out[2:4] = rng.uniform(8, 200, (2, n))
    out[4:] = rng.uniform(0, 0.01, (classes, n))
    objects = rng.integers(0, n, 60)
    for k, i in enumerate(objects):  # 25 overlapping candidates per object
        idx = rng.integers(0, n, 25)
        out[:4, idx] = out[:4, i : i + 1] + rng.normal(0, 3, (4, 25))
        out[4 + (2, 7, 5, 0)[k % 4], idx] = rng.uniform(0.05, 0.95, 25)
    return out[None]


def build(path: Path, output: np.ndarray) -> Path:
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    node = helper.make_node("Constant", [], ["output0"], value=numpy_helper.from_array(output))
    graph = helper.make_graph(
        [node],
        "yolov8_shaped",
        [helper.make_tensor_value_info("images", TensorProto.FLOAT, [1, 3, 640, 640])],
        [helper.make_tensor_value_info("output0", TensorProto.FLOAT, list(output.shape))],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    onnx.save(model, str(path))
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--size", default="1280x720")
    args = parser.parse_args()
    w, h = (int(v) for v in args.size.split("x"))
    rng = np.random.default_rng(0)
    frame = cv2.GaussianBlur(rng.integers(0, 255, (h, w, 3), dtype=np.uint8), (5, 5), 0)
    cv2.setNumThreads(1)
    with tempfile.TemporaryDirectory() as tmp:
        det = OnnxDetector(
            build(Path(tmp) / "m.onnx", yolov8_output(rng)), DetectorSettings(threads=1)
        )
        for _ in range(10):  # warm-up
            det.detect(frame)
        pre, inf, post, n_boxes = [], [], [], 0
        for _ in range(args.frames):
            t0 = time.process_time()
            blob, box = det.preprocess(frame)
            t1 = time.process_time()
            outputs = det.session.run(det.output_names, {det.input_name: blob})
            t2 = time.process_time()
            n_boxes = len(det.postprocess(outputs, box, w, h, 0))
            t3 = time.process_time()
            pre.append((t1 - t0) * 1e3)
            inf.append((t2 - t1) * 1e3)
            post.append((t3 - t2) * 1e3)
    print(f"frame {w}×{h}, output [1, 84, 8400], {n_boxes} boxes kept, {args.frames} frames")
    print(f"{'step':<22}{'median ms':>10}{'p95 ms':>10}")
    total = np.add(pre, post)
    for name, values in [
        ("preprocess", pre),
        ("inference (no-op)", inf),
        ("postprocess", post),
        ("pre + post", total),
    ]:
        print(f"{name:<22}{np.median(values):>10.3f}{np.percentile(values, 95):>10.3f}")


if __name__ == "__main__":
    main()
