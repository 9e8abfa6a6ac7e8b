"""KITTI raw drives with LiDAR: calibration, Velodyne scans, and vehicle boxes from the LiDAR.

Layout of a drive folder (as ``../shared/data/kitti_raw_lead``)::

    image_02/0000000000.png ...      colour frames of cam 2 (10 Hz)
    velodyne_front/0000000000.bin    Velodyne scan of each frame: float32 rows x y z reflectance
    calib.txt                        P2, R0_rect, Tr_velo_to_cam (KITTI tracking layout)

Frames: LiDAR x forward, y left, z up (metres); rectified camera x right, y down, z forward.
A LiDAR point ``X`` (homogeneous) projects as ``P2 · R0_rect · Tr_velo_to_cam · X``.

Ground truth from the LiDAR (:func:`lidar_vehicle_boxes`): fit the ground plane (RANSAC), drop
the ground and everything higher than a vehicle, cluster the rest on a bird's-eye grid
(connected cells), keep clusters of vehicle size, and give each its 2D box in the image and its
distance. The distance ``z`` is the longitudinal distance (rectified camera z) of the cluster's
**nearest face**: the 5th percentile of its points' z. The box is the box of the projected
points, extended down to the ground under them (the points dropped onto the fitted plane), so
the box bottom is the target's ground-contact row — the row eq. 1 reads — even though the ground
removal takes away the lowest few centimetres of the vehicle.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from slopedist.core.camera import KITTI_CAMERA_HEIGHT_M, Camera, read_kitti_calib
from slopedist.core.errors import InputFileError, MissingInputError
from slopedist.io.detections.boxes import BoxTable, concat_boxes

FloatArray = NDArray[np.float64]

IMAGE_FOLDER = "image_02"
VELODYNE_FOLDERS = ("velodyne_front", "velodyne_points/data", "velodyne")


@dataclass(frozen=True)
class KittiRawCalib:
    """Calibration of a KITTI raw drive.

    Attributes:
        P_rect_20: ``(3, 4)`` projection of rectified cam 2 (the ``P2`` line).
        R_rect_00: ``(3, 3)`` rectifying rotation (``R0_rect``).
        T_cam0_velo: ``(4, 4)`` LiDAR → (unrectified) cam 0 (``Tr_velo_to_cam``).
    """

    P_rect_20: FloatArray
    R_rect_00: FloatArray
    T_cam0_velo: FloatArray

    @classmethod
    def from_file(cls, path: str | Path) -> KittiRawCalib:
        """Read ``P2``, ``R0_rect`` (or ``R_rect``) and ``Tr_velo_to_cam`` (or ``Tr_velo_cam``)."""
        calib = read_kitti_calib(path)

        def pick(*names: str) -> NDArray[np.float64]:
            for n in names:
                if n in calib:
                    return calib[n]
            raise InputFileError(path, f"no '{names[0]}:' line (found: {', '.join(calib)})")

        T = np.eye(4)
        T[:3, :] = pick("Tr_velo_to_cam", "Tr_velo_cam").reshape(3, 4)
        return cls(pick("P2").reshape(3, 4), pick("R0_rect", "R_rect").reshape(3, 3), T)

    @property
    def T_rect_velo(self) -> FloatArray:
        """``(4, 4)`` LiDAR → rectified camera frame: ``R0_rect · Tr_velo_to_cam``."""
        R = np.eye(4)
        R[:3, :3] = self.R_rect_00
        return R @ self.T_cam0_velo

    def camera(self, height_m: float = KITTI_CAMERA_HEIGHT_M) -> Camera:
        """The :class:`Camera` of cam 2 (f, c_x, c_y from ``P2``)."""
        return Camera.from_projection(self.P_rect_20, height_m)


def read_velodyne(path: str | Path) -> NDArray[np.float32]:
    """A Velodyne ``.bin`` scan → ``(N, 4)`` float32 rows ``x y z reflectance`` (LiDAR frame, m).

    Raises:
        MissingInputError: no such file.
        InputFileError: the file size is not a whole number of 16-byte rows.
    """
    path = Path(path)
    if not path.is_file():
        raise MissingInputError(f"Velodyne scan not found: {path}")
    raw = np.fromfile(path, dtype=np.float32)
    if raw.size % 4:
        raise InputFileError(
            path,
            f"{raw.size * 4} bytes is not a whole number of 16-byte "
            "rows (x y z reflectance as float32)",
        )
    return raw.reshape(-1, 4)


def velo_to_rect(points_velo: ArrayLike, calib: KittiRawCalib) -> FloatArray:
    """LiDAR points ``(N, 3)`` → rectified camera frame ``(N, 3)`` (metres)."""
    p = np.asarray(points_velo, dtype=float)[:, :3]
    T = calib.T_rect_velo
    return np.asarray(p @ T[:3, :3].T + T[:3, 3])


def project_velo_to_image(
    points_velo: ArrayLike, calib: KittiRawCalib
) -> tuple[FloatArray, FloatArray]:
    """Project LiDAR points ``(N, 3+)`` into cam 2: ``P2 · R0_rect · Tr_velo_to_cam · X``.

    Returns:
        ``uv`` ``(N, 2)`` pixel coordinates (column, row) and ``z`` ``(N,)`` the points' depth
        in the rectified camera frame (metres; ``uv`` is NaN where ``z ≤ 0``).
    """
    X = velo_to_rect(points_velo, calib)
    uvw = X @ calib.P_rect_20[:, :3].T + calib.P_rect_20[:, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = uvw[:, :2] / uvw[:, 2:3]
    uv[X[:, 2] <= 0] = np.nan
    return uv, X[:, 2]


def fit_ground_plane(
    points_velo: ArrayLike,
    *,
    max_height_m: float = -1.0,
    tolerance_m: float = 0.12,
    iterations: int = 200,
    seed: int = 0,
) -> tuple[FloatArray, float]:
    """RANSAC plane through the ground points of a scan (LiDAR frame, z up).

    Candidates are the points with ``z < max_height_m`` (the Velodyne sits about 1.73 m above
    the road) within 3–40 m ahead; the plane with most points within ``tolerance_m`` is refined
    by least squares on its inliers.

    Returns:
        ``(n, d)`` with ``n`` the unit normal pointing up, so ``n·X + d`` is a point's height
        above the ground, metres.
    """
    p = np.asarray(points_velo, dtype=float)[:, :3]
    cand = p[(p[:, 2] < max_height_m) & (p[:, 0] > 3) & (p[:, 0] < 40)]
    if cand.shape[0] < 3:
        raise InputFileError("<scan>", "too few ground points to fit the road plane")
    rng = np.random.default_rng(seed)
    best = np.zeros(cand.shape[0], dtype=bool)
    for _ in range(iterations):
        a, b, c = cand[rng.choice(cand.shape[0], 3, replace=False)]
        n = np.cross(b - a, c - a)
        norm = np.linalg.norm(n)
        if norm < 1e-9 or abs(n[2]) / norm < 0.9:  # degenerate or far from horizontal
            continue
        n = n / norm
        inl = np.abs((cand - a) @ n) < tolerance_m
        if inl.sum() > best.sum():
            best = inl
    if best.sum() < 3:
        raise InputFileError("<scan>", "no road plane found among the low points")
    q = cand[best]
    centre = q.mean(axis=0)
    n = np.linalg.eigh(np.cov((q - centre).T))[1][:, 0]  # normal: least-variance direction
    if n[2] < 0:
        n = -n
    return n, float(-n @ centre)


def cluster_bev(points_xy: ArrayLike, cell_m: float = 0.3) -> NDArray[np.int64]:
    """Cluster points on a bird's-eye grid: occupied cells that touch (8-neighbourhood) form
    one cluster.

    Args:
        points_xy: ``(N, 2)`` ground-plane coordinates, metres.
        cell_m: grid cell size, metres (points closer than about one cell join).

    Returns:
        ``(N,)`` cluster label per point, 0, 1, ... (−1 for an empty input).
    """
    xy = np.asarray(points_xy, dtype=float).reshape(-1, 2)
    if xy.shape[0] == 0:
        return np.zeros(0, dtype=np.int64)
    ij = np.floor((xy - xy.min(axis=0)) / cell_m).astype(np.int64)
    grid = np.zeros(tuple(ij.max(axis=0) + 1), dtype=bool)
    grid[ij[:, 0], ij[:, 1]] = True
    labels, _ = ndimage.label(grid, structure=np.ones((3, 3), dtype=bool))
    return labels[ij[:, 0], ij[:, 1]].astype(np.int64) - 1


@dataclass(frozen=True)
class VehicleClusterParams:
    """What counts as a vehicle cluster (metres, points).

    Attributes:
        min_height_m / max_height_m: points kept above the ground plane (ground and bridges,
            trees above the vehicles are dropped).
        cell_m: bird's-eye grid cell of the clustering.
        min_points: fewest points (inside the image) of a cluster.
        min_top_m / max_top_m: range of the cluster's highest point above the ground.
        min_extent_m / max_extent_m: range of the larger of its two ground-plane extents.
        max_range_m: farthest cluster (nearest-face z) kept.
        near_quantile: quantile of the cluster's z taken as its nearest face.
    """

    min_height_m: float = 0.25
    max_height_m: float = 3.8
    cell_m: float = 0.3
    min_points: int = 40
    min_top_m: float = 1.0
    max_top_m: float = 4.5
    min_extent_m: float = 1.2
    max_extent_m: float = 18.0
    max_range_m: float = 60.0
    near_quantile: float = 0.05


@dataclass
class _Cluster:
    box: FloatArray
    z_near: float
    z_median: float
    x_centre: float
    n_points: int
    truncated: bool
    centre_xy: FloatArray = field(default_factory=lambda: np.zeros(2))


def lidar_vehicle_boxes(
    points_velo: ArrayLike,
    calib: KittiRawCalib,
    image_size: tuple[int, int],
    frame: int = 0,
    params: VehicleClusterParams | None = None,
) -> BoxTable:
    """Vehicle boxes of one scan, with their LiDAR distances (see the module docstring).

    Args:
        points_velo: ``(N, 3+)`` LiDAR points (x forward, y left, z up), metres.
        calib: the drive's calibration.
        image_size: ``(width, height)`` of cam 2 images, pixels.
        frame: frame index written into the table.
        params: cluster thresholds.

    Returns:
        A :class:`BoxTable` (class ``"Car"``, no track ids) with extra columns ``z``
        (nearest-face longitudinal distance, m), ``z_median`` (median z of the cluster's points,
        m), ``x`` (lateral position of the cluster centre in the camera frame, m, right
        positive), ``n_points`` and ``truncated`` (1 when the box was cut by the image border,
        0 otherwise), sorted by ``z``.
    """
    prm = params or VehicleClusterParams()
    scan = _scan_points(points_velo, calib, image_size, prm)
    found: list[_Cluster] = []
    for lab in np.unique(scan.labels[scan.inside]):
        cluster = _vehicle_cluster(scan, lab, image_size, prm)
        if cluster is not None:
            found.append(cluster)
    found.sort(key=lambda c: c.z_near)
    return BoxTable.build(
        np.full(len(found), frame, dtype=np.int64),
        np.asarray([c.box for c in found], dtype=float).reshape(-1, 4),
        z=np.asarray([c.z_near for c in found], dtype=float),
        z_median=np.asarray([c.z_median for c in found], dtype=float),
        x=np.asarray([c.x_centre for c in found], dtype=float),
        n_points=np.asarray([c.n_points for c in found], dtype=np.int64),
        truncated=np.asarray([int(c.truncated) for c in found], dtype=np.int64),
        centre_xy=np.asarray([c.centre_xy for c in found], dtype=float).reshape(-1, 2),
    )


@dataclass(frozen=True)
class _Scan:
    """The points of one scan above the ground, ``(N, ...)`` each.

    Attributes:
        pts: LiDAR points (x forward, y left, z up), metres; height: above the ground plane, m.
        uv, z: their cam-2 pixels and camera z (m); inside: in front and inside the image.
        uv_feet: the pixels of their feet on the ground plane.
        X_rect: the points in the rectified camera frame, metres.
        labels: bird's-eye cluster of each point.
    """

    pts: FloatArray
    height: FloatArray
    uv: FloatArray
    z: FloatArray
    inside: NDArray[np.bool_]
    uv_feet: FloatArray
    X_rect: FloatArray
    labels: NDArray[np.int64]


def _scan_points(
    points_velo: ArrayLike,
    calib: KittiRawCalib,
    image_size: tuple[int, int],
    prm: VehicleClusterParams,
) -> _Scan:
    """Drop the ground (and what is above the vehicles), project and cluster the rest."""
    pts = np.asarray(points_velo, dtype=float)[:, :3]
    n, d = fit_ground_plane(pts)
    height = pts @ n + d
    keep = (height > prm.min_height_m) & (height < prm.max_height_m)
    pts, height = pts[keep], height[keep]
    uv, z = project_velo_to_image(pts, calib)
    w, h = image_size
    inside = (z > 0.5) & (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
    # cluster on the ground plane (x forward, y left of the LiDAR frame, good enough on a road)
    labels = cluster_bev(pts[:, :2], prm.cell_m)
    feet = pts - height[:, None] * n
    uv_feet, _ = project_velo_to_image(feet, calib)
    X_rect = velo_to_rect(pts, calib)
    return _Scan(pts, height, uv, z, inside, uv_feet, X_rect, labels)


def _vehicle_cluster(
    scan: _Scan, lab: int, image_size: tuple[int, int], prm: VehicleClusterParams
) -> _Cluster | None:
    """Cluster ``lab`` of the scan as a vehicle's box, or None when it is no vehicle (too few
    points in the image, the wrong size or height, too far)."""
    pts, height, uv, z = scan.pts, scan.height, scan.uv, scan.z
    w, h = image_size
    sel = (scan.labels == lab) & scan.inside
    if sel.sum() < prm.min_points:
        return None
    whole = scan.labels == lab
    extent = np.ptp(pts[whole, :2], axis=0)
    top = float(height[whole].max())
    if not (
        prm.min_extent_m <= extent.max() <= prm.max_extent_m
        and prm.min_top_m <= top <= prm.max_top_m
    ):
        return None
    z_near = float(np.quantile(z[sel], prm.near_quantile))
    if z_near > prm.max_range_m:
        return None
    u, v = uv[sel, 0], uv[sel, 1]
    foot_rows = scan.uv_feet[sel, 1]
    bottom = float(max(v.max(), np.nanmax(foot_rows)))
    box = np.array([u.min(), v.min(), u.max(), bottom])
    truncated = bool(
        (sel.sum() < whole.sum() * 0.95)
        or box[0] <= 1
        or box[2] >= w - 2
        or box[1] <= 1
        or box[3] >= h - 1
    )
    box = np.clip(box, [0, 0, 0, 0], [w - 1, h - 1, w - 1, h - 1])
    return _Cluster(
        box,
        z_near,
        float(np.median(z[sel])),
        float(np.median(scan.X_rect[sel, 0])),
        int(sel.sum()),
        truncated,
        np.median(pts[whole, :2], axis=0),
    )


@dataclass(frozen=True)
class KittiRawDrive:
    """A KITTI raw drive folder (see the module docstring).

    Attributes:
        root: the folder.
        calib: its calibration.
        image_paths: ``{frame index: image file}`` of cam 2.
        velodyne_paths: ``{frame index: scan file}``.
    """

    root: Path
    calib: KittiRawCalib
    image_paths: dict[int, Path]
    velodyne_paths: dict[int, Path]

    @classmethod
    def open(cls, root: str | Path) -> KittiRawDrive:
        """Open a drive folder; fails naming what is missing."""
        root = Path(root)
        if not (root / "calib.txt").is_file():
            raise MissingInputError(f"no KITTI raw drive at {root}: expected calib.txt there")
        if not (root / IMAGE_FOLDER).is_dir():
            raise MissingInputError(f"no {IMAGE_FOLDER}/ folder in {root}")
        velo_dir = next((root / v for v in VELODYNE_FOLDERS if (root / v).is_dir()), None)
        if velo_dir is None:
            raise MissingInputError(f"no Velodyne folder ({', '.join(VELODYNE_FOLDERS)}) in {root}")
        images = {int(p.stem): p for p in (root / IMAGE_FOLDER).glob("*.png") if p.stem.isdigit()}
        scans = {int(p.stem): p for p in velo_dir.glob("*.bin") if p.stem.isdigit()}
        return cls(root, KittiRawCalib.from_file(root / "calib.txt"), images, scans)

    @property
    def image_dir(self) -> Path:
        return self.root / IMAGE_FOLDER

    @property
    def calib_path(self) -> Path:
        return self.root / "calib.txt"

    def frames(self) -> list[int]:
        """Frame indices that have both an image and a scan, sorted."""
        return sorted(set(self.image_paths) & set(self.velodyne_paths))

    def lidar_boxes(
        self,
        image_size: tuple[int, int],
        params: VehicleClusterParams | None = None,
        max_match_m: float = 2.0,
    ) -> BoxTable:
        """:func:`lidar_vehicle_boxes` of every frame, with track ids linking each cluster to
        the nearest cluster (ground-plane centre within ``max_match_m``) of the frame before."""
        parts = [
            lidar_vehicle_boxes(
                read_velodyne(self.velodyne_paths[k]), self.calib, image_size, k, params
            )
            for k in self.frames()
        ]
        return link_tracks(parts, max_match_m)


def link_tracks(frames: list[BoxTable], max_match_m: float = 2.0) -> BoxTable:
    """Give the clusters of consecutive frames track ids by greedy nearest-centre matching on
    the ground plane (column ``centre_xy``, metres); a cluster without a match starts a track."""
    next_id = 0
    prev_xy = np.zeros((0, 2))
    prev_id = np.zeros(0, dtype=np.int64)
    out: list[BoxTable] = []
    for table in frames:
        xy = table.extra["centre_xy"].reshape(-1, 2)
        ids = np.full(len(table), -1, dtype=np.int64)
        if len(prev_xy) and len(xy):
            dist = np.linalg.norm(xy[:, None, :] - prev_xy[None, :, :], axis=2)
            for flat in np.argsort(dist, axis=None):
                i, j = np.unravel_index(flat, dist.shape)
                if dist[i, j] > max_match_m:
                    break
                if ids[i] < 0 and prev_id[j] >= 0:
                    ids[i] = prev_id[j]
                    prev_id = prev_id.copy()
                    prev_id[j] = -1
        for i in np.flatnonzero(ids < 0):
            ids[i] = next_id
            next_id += 1
        out.append(BoxTable(table.frame, table.boxes, ids, table.score, table.cls, table.extra))
        prev_xy, prev_id = xy, ids
    return concat_boxes(out)
