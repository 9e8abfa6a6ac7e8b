"""Adapters for in-memory detections: fake ultralytics Results and supervision Detections."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from slopedist.core.errors import DataMismatchError
from slopedist.io.detections.adapters import from_frames, from_supervision, from_ultralytics

XYXY = np.array([[10, 20, 110, 80], [200, 50, 260, 90], [5, 5, 15, 40]], float)
CONF = np.array([0.9, 0.6, 0.8])
CLS = np.array([2.0, 7.0, 0.0])  # car, truck, person


class FakeTensor:
    """Quacks like a torch tensor: ``.cpu().numpy()``."""

    def __init__(self, a: np.ndarray) -> None:
        self.a = a

    def cpu(self) -> FakeTensor:
        return self

    def numpy(self) -> np.ndarray:
        return self.a


def _results(ids: np.ndarray | None = None) -> SimpleNamespace:
    boxes = SimpleNamespace(
        xyxy=FakeTensor(XYXY),
        conf=FakeTensor(CONF),
        cls=FakeTensor(CLS),
        id=None if ids is None else FakeTensor(ids),
    )
    return SimpleNamespace(boxes=boxes, names={0: "person", 2: "car", 7: "truck"})


def test_ultralytics_results_map_classes_and_keep_track_ids() -> None:
    table = from_ultralytics(_results(np.array([4.0, 9.0, 1.0])), frame=12)
    np.testing.assert_array_equal(table.boxes, XYXY[:2])
    assert list(table.cls) == ["Car", "Truck"] and table.frame.tolist() == [12, 12]
    assert table.track_id.tolist() == [4, 9]
    np.testing.assert_allclose(table.score, [0.9, 0.6])


def test_ultralytics_list_is_consecutive_frames_without_tracks() -> None:
    table = from_ultralytics([_results(), _results()], frame=3)
    assert table.frame.tolist() == [3, 3, 4, 4] and np.all(table.track_id == -1)


def test_supervision_detections_with_optional_fields() -> None:
    det = SimpleNamespace(xyxy=XYXY, confidence=CONF, class_id=CLS.astype(int), tracker_id=None)
    table = from_supervision(det, frame=2, class_map={0: "Pedestrian"})
    assert list(table.cls) == ["Pedestrian"] and table.boxes.tolist() == [[5, 5, 15, 40]]
    bare = from_supervision(
        SimpleNamespace(xyxy=XYXY, confidence=None, class_id=None, tracker_id=np.array([1, 2, 3]))
    )
    assert len(bare) == 3 and list(bare.cls) == ["Car"] * 3 and np.all(np.isnan(bare.score))
    assert bare.track_id.tolist() == [1, 2, 3]


def test_from_frames_dispatches_on_the_object() -> None:
    det = SimpleNamespace(xyxy=XYXY, confidence=CONF, class_id=CLS, tracker_id=None)
    table = from_frames([(0, _results()), (1, det)])
    assert table.frame.tolist() == [0, 0, 1, 1]


def test_mismatched_lengths_and_wrong_objects_are_clear_errors() -> None:
    det = SimpleNamespace(xyxy=XYXY, confidence=CONF[:2], class_id=None, tracker_id=None)
    with pytest.raises(DataMismatchError, match="3 boxes but 2 values of 'score'"):
        from_supervision(det)
    with pytest.raises(DataMismatchError, match=r"boxes\.xyxy"):
        from_ultralytics(SimpleNamespace())
    with pytest.raises(DataMismatchError, match=r"\(N, 4\)"):
        from_supervision(SimpleNamespace(xyxy=np.zeros(3)))
