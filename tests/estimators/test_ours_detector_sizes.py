"""``ours`` with the vehicle size a detector gives: in place of the class prior, with its σ."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from slopedist.core.camera import Camera
from slopedist.estimators import make_estimator
from slopedist.estimators.base import FrameInput
from slopedist.estimators.ours.class_table import ClassTable
from slopedist.estimators.ours.cues import project_box
from slopedist.estimators.ours.priors import CLASS_PRIORS, DimensionPrior, yaw_grid
from slopedist.io.detections.boxes import BoxTable
from slopedist.io.detections.readers import read_box_file
from slopedist.odometry.base import RotationTrack
from slopedist.streaming.step import estimate_sequence

CAM = Camera(721.5, 609.6, 172.9, 1.65, 0.0)
VAN = (2.60, 1.95, 5.20)
"""A tall van (height, width, length, m), taller than the camera: its box is its rear face."""


def _rear_face_box(z_centre_m: float, dims: tuple[float, float, float]) -> np.ndarray:
    """The box of a vehicle straight ahead (ψ = 0, centred on the optical axis) on the flat
    road under the camera, by hand: taller than the camera, every edge is its rear face's, at
    z_n = z − L/2: rows c_y + f·(h − H)/z_n (roof) and c_y + f·h/z_n (road), columns
    c_x ± f·(W/2)/z_n."""
    H, W, L = dims
    f, cx, cy, h = CAM.f, CAM.c_x, CAM.c_y, CAM.height_m
    z_n = z_centre_m - L / 2
    return np.array(
        [cx - f * W / 2 / z_n, cy + f * (h - H) / z_n, cx + f * W / 2 / z_n, cy + f * h / z_n]
    )


def _frames(
    box: np.ndarray, n: int, sizes: dict[str, float] | None, cls: str = "Car"
) -> list[FrameInput]:
    frames = []
    for k in range(n):
        extra = {c: np.array([v]) for c, v in (sizes or {}).items()}
        table = BoxTable.build([k], box[None], [1], classes=np.array([cls], dtype=object), **extra)
        frames.append(FrameInput(k, 0.1 * k, 0.0, table, R_world_cam=np.eye(3)))
    return frames


def _ours(frames: list[FrameInput], **options: object) -> tuple[float, float]:
    """``ours``' distance (vehicle centre) and σ at the last frame, m."""
    est = make_estimator("ours", CAM, **options)
    for frame in frames:
        out = est.estimate(frame)
    return float(out.distance_m[0]), float(out.extra["sigma_m"][0])


def test_the_hand_computed_box_is_the_projected_one() -> None:
    box = _rear_face_box(40.0, VAN)
    np.testing.assert_allclose(
        box, project_box(CAM.f, CAM.c_x, CAM.c_y, 1.65, 0.0, 40.0, 0.0, np.array(VAN))
    )


@pytest.mark.parametrize("z_m", [20.0, 40.0, 60.0])
def test_a_true_size_recovers_the_distance_a_wrong_class_prior_misses(z_m: float) -> None:
    """A van boxed as ``Car``: the car prior (1.53 m tall) reads its 2.6 m tall box as a car's
    at about 1.53/2.6 of its distance (the ground contact pulls back, loosely beyond ~10 m);
    with the van's own dimensions as the detector's size (σ 5 %) every cue agrees."""
    box = _rear_face_box(z_m, VAN)
    sized = dict(zip(("height_m", "width_m", "length_m"), VAN), size_sigma_pct=5.0)
    prior_d, _ = _ours(_frames(box, 5, None))
    sized_d, sized_sigma = _ours(_frames(box, 5, sized))
    assert abs(sized_d - z_m) < 0.02 * z_m
    assert abs(sized_d - z_m) < 0.25 * abs(prior_d - z_m)
    assert prior_d < z_m  # the prior's vehicle is smaller: nearer
    assert sized_sigma < 0.08 * z_m


@pytest.mark.parametrize("z_m", [20.0, 60.0])
def test_a_wrong_detector_size_is_believed_as_far_as_its_sigma_says(z_m: float) -> None:
    """Every dimension 10 % too big: with σ 2 % the vehicle is put ~10 % too far, its σ
    tight; with σ 50 % its σ widens to cover the error, and near (20 m), where the ground
    contact is tight, the ground contact carries it back towards the truth."""
    box = _rear_face_box(z_m, VAN)
    big = {"height_m": VAN[0] * 1.1, "width_m": VAN[1] * 1.1, "length_m": VAN[2] * 1.1}
    tight, tight_sigma = _ours(_frames(box, 5, {**big, "size_sigma_pct": 2.0}))
    loose, loose_sigma = _ours(_frames(box, 5, {**big, "size_sigma_pct": 50.0}))
    assert tight == pytest.approx(1.1 * z_m, rel=0.03)
    assert tight_sigma < 0.03 * z_m < loose_sigma
    assert abs(loose - z_m) < 1.0 * loose_sigma
    if z_m < 30:
        assert abs(loose - z_m) < 0.6 * abs(tight - z_m)


def test_unknown_sizes_change_nothing() -> None:
    """NaN sizes (and a σ with no size) give the class prior's estimate bit for bit."""
    box = _rear_face_box(30.0, VAN)
    unknown = {"height_m": np.nan, "width_m": np.nan, "length_m": np.nan, "size_sigma_pct": 5.0}
    assert _ours(_frames(box, 4, unknown)) == _ours(_frames(box, 4, None))


def test_a_detector_size_makes_a_generic_class_specific() -> None:
    """With ``generic_classes`` the class ``Car`` is a mixture of vehicle types; a box whose
    detector gives its size is read with that size alone (no type to guess): the estimate of
    a class whose prior is that size."""
    box = _rear_face_box(40.0, VAN)
    sized = dict(zip(("height_m", "width_m", "length_m"), VAN), size_sigma_pct=5.0)
    generic = _ours(_frames(box, 5, sized), generic_classes=("Car",))
    specific = _ours(_frames(box, 5, sized))
    assert generic == pytest.approx(specific, rel=1e-9)


def test_sized_constants_are_those_of_a_class_of_that_size() -> None:
    """A target with a detector size gathers the constants a class table gives a class whose
    prior is that size (σ the detector's, the class's height-width correlation), in every
    layout (size modes; types of a generic class); a dimension left unknown keeps the class
    prior's value and σ."""
    car = CLASS_PRIORS["Car"]
    dims = np.array([[2.6, np.nan, 5.2], [np.nan, np.nan, np.nan]])
    sigma = np.array([[0.13, np.nan, 0.26], [np.nan, np.nan, np.nan]])
    as_class = DimensionPrior(2.6, car.width_m, 5.2, 0.13, car.width_sigma_m, 0.26, car.corr_hw)
    names = np.array(["Car", "Car"], dtype=object)
    for generic, n_modes in (((), 3), (("Car",), 3)):
        got = ClassTable(None, yaw_grid(), generic, n_modes=n_modes).gather(names, (dims, sigma))
        want = ClassTable({"Sized": as_class, "Car": car}, yaw_grid(), generic, n_modes=n_modes)
        ref = want.gather(np.array(["Sized", "Car"], dtype=object))
        assert got.generic.tolist() == [False, bool(generic)]
        for a, b in zip(got.hypotheses, ref.hypotheses, strict=True):
            if generic:  # the sized target's planes over the types, the others of no weight
                k = yaw_grid().size
                np.testing.assert_allclose(a[0], np.tile(b[0, :k], a.shape[1] // k))
                np.testing.assert_array_equal(a[1], b[1])
            else:
                np.testing.assert_allclose(a, b)
        np.testing.assert_allclose(got.height_m, ref.height_m)
        np.testing.assert_allclose(got.height_log_sigma, ref.height_log_sigma)
        if generic:
            assert got.type_log_weight is not None
            assert got.type_log_weight[0, 0] == 0.0 and (got.type_log_weight[0, 1:] < -100).all()


def test_a_box_csv_with_sizes_reaches_ours_through_the_batch_step(tmp_path: Path) -> None:
    """The size columns of a box CSV survive the reader and the per-frame cut of the batch
    step: ``ours`` and ``ours-offline`` place the van as its size says."""
    z = 40.0
    box = _rear_face_box(z, VAN)
    path = tmp_path / "boxes.csv"
    rows = [f"{k},{','.join(f'{v:.4f}' for v in box)},1,Car,2.6,1.95,5.2,5" for k in range(6)]
    path.write_text(
        "frame,left,top,right,bottom,track_id,class,height_m,width_m,length_m,"
        "size_sigma_pct\n" + "\n".join(rows) + "\n"
    )
    table = read_box_file(path)
    plain = BoxTable(table.frame, table.boxes, table.track_id, table.score, table.cls)
    t = np.arange(6) * 0.1
    track = RotationTrack.from_arrays(t, np.broadcast_to(np.eye(3), (6, 3, 3)))
    for method in ("ours", "ours-offline"):
        sized = estimate_sequence(make_estimator(method, CAM), table, t, track).estimates
        prior = estimate_sequence(make_estimator(method, CAM), plain, t, track).estimates
        assert abs(sized.distance_m[-1] - z) < 0.02 * z < abs(prior.distance_m[-1] - z)
