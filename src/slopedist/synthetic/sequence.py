"""A rendered synthetic sequence: frames, true depth, exact and noisy boxes, one at a time.

Convention: as :mod:`~slopedist.synthetic.scene` (camera frame x right, y down,
z forward; boxes ``(left, top, right, bottom)`` pixels; metres, seconds, radians). Memory holds
the scenario's tables and one frame.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from slopedist.core.camera import Camera
from slopedist.io.detections.boxes import BoxTable
from slopedist.synthetic.noise import BoxNoiseSpec, noisy_boxes
from slopedist.synthetic.polygons import vehicle_polygons
from slopedist.synthetic.render import Rendered, Renderer
from slopedist.synthetic.scene import Scenario, SceneTruth, simulate_truth
from slopedist.synthetic.textures import LaneLayout
from slopedist.synthetic.world import static_world

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class SyntheticFrame:
    """One frame of a synthetic sequence.

    Attributes:
        index: frame index; timestamp_s: seconds.
        image: BGR ``H×W×3`` uint8; depth_m: ``H×W`` float32 metres (``+inf`` = sky; made
            on first access).
        rendered: the renderer's output (labels, the target seen at each pixel, depth).
        visible_share: ``(M,)`` share of each target's projected silhouette (inside the image)
            that is not hidden by the road or another vehicle; 0 when not in view.
        exact: the exact boxes of the targets in view, with columns ``z`` (KITTI z of the box's
            bottom centre, m), ``truncation`` and ``visible_share``.
        detections: the noisy boxes the detector model reports (track ids kept).
    """

    index: int
    timestamp_s: float
    image: NDArray[np.uint8]
    rendered: Rendered = field(repr=False)
    visible_share: FloatArray
    exact: BoxTable
    detections: BoxTable

    @property
    def depth_m(self) -> NDArray[np.float32]:
        """``H×W`` float32 metres along the camera z axis (``+inf`` = sky)."""
        return self.rendered.depth_m


class SyntheticSequence:
    """Renders a :class:`~slopedist.synthetic.scene.Scenario` frame by frame.

    Attributes:
        scenario, road, truth (:class:`SceneTruth`), camera (the
        :class:`~slopedist.core.camera.Camera` for estimators), renderer.
    """

    def __init__(self, scenario: Scenario, noise: BoxNoiseSpec | None = None) -> None:
        self.scenario = scenario
        self.noise = noise or scenario.noise
        self.road = scenario.build_road()
        self.truth: SceneTruth = simulate_truth(scenario, self.road)
        self.camera: Camera = scenario.camera.camera()
        spec = scenario.road
        world = scenario.world
        polys = static_world(
            self.road,
            spec.corridor_half_width_m,
            spec.half_width_m,
            world.structure_height_m,
            world.structure_segment_m,
            world.post_spacing_m,
            world.object_spacing_m,
            scenario.seed,
        )
        cam = scenario.camera
        self.renderer = Renderer(
            polys,
            cam.K,
            cam.image_width,
            cam.image_height,
            LaneLayout(spec.half_width_m, spec.lanes, spec.lane_width_m),
            scenario.seed,
        )
        self._colours = np.array([t.colour_bgr for t in scenario.targets], dtype=float)
        self._half_len = np.array([0.5 * t.length_m for t in scenario.targets])

    def __len__(self) -> int:
        return self.truth.n_frames

    @property
    def image_size(self) -> tuple[int, int]:
        """``(width, height)`` in pixels."""
        return self.scenario.camera.image_width, self.scenario.camera.image_height

    def render(self, k: int) -> Rendered:
        """Render frame ``k`` (image, depth, per-pixel target index)."""
        tr = self.truth
        s_cam = float(tr.ego_s[k] + self.scenario.camera.rig.forward_m)
        s_t = tr.target_s[k]
        dyn = vehicle_polygons(
            tr.corners_world[k],
            self._colours,
            s_t - self._half_len,
            s_t + self._half_len,
            np.arange(len(s_t)),
        )
        return self.renderer.render(tr.R_world_cam[k], tr.centre_world[k], s_cam, dyn, k)

    def visible_share(self, k: int, rendered: Rendered) -> FloatArray:
        """Share of each target's silhouette (clipped to the image) seen in ``rendered``."""
        tr = self.truth
        w, h = self.image_size
        counts = rendered.visible_pixels(len(tr.track_ids))
        K = self.scenario.camera.K
        share = np.zeros(len(tr.track_ids))
        rect = np.array(
            [[-0.5, -0.5], [w - 0.5, -0.5], [w - 0.5, h - 0.5], [-0.5, h - 0.5]], np.float32
        )
        for m in np.flatnonzero(tr.in_view[k]):
            pc = tr.corners_cam[k, m]
            px = (pc[:, :2] * K[0, 0]) / pc[:, 2:3] + K[:2, 2]
            hull = cv2.convexHull(px.astype(np.float32))
            area, _ = cv2.intersectConvexConvex(hull, rect)
            if area > 0:
                share[m] = min(1.0, counts[m] / area)
        return share

    def exact_boxes(self, k: int, visible_share: FloatArray | None = None) -> BoxTable:
        """The exact boxes of frame ``k``'s targets in view."""
        tr = self.truth
        m = np.flatnonzero(tr.in_view[k])
        vis = visible_share[m] if visible_share is not None else np.full(len(m), np.nan)
        cls = np.array([self.scenario.targets[i].cls for i in m], dtype=object)
        return BoxTable.build(
            np.full(len(m), k),
            tr.box[k, m],
            tr.track_ids[m],
            np.ones(len(m)),
            cls,
            z=tr.z_m[k, m],
            truncation=tr.truncation[k, m],
            visible_share=vis,
        )

    def detections(self, k: int, visible_share: FloatArray) -> BoxTable:
        """The noisy detector boxes of frame ``k`` (see :mod:`.noise`)."""
        tr = self.truth
        boxes, found = noisy_boxes(
            tr.box[k], visible_share, self.noise, self.image_size, self.scenario.seed, k
        )
        m = np.flatnonzero(found)
        cls = np.array([self.scenario.targets[i].cls for i in m], dtype=object)
        return BoxTable.build(np.full(len(m), k), boxes[m], tr.track_ids[m], np.ones(len(m)), cls)

    def frame(self, k: int) -> SyntheticFrame:
        """Render frame ``k`` with its boxes."""
        r = self.render(k)
        share = self.visible_share(k, r)
        return SyntheticFrame(
            k,
            float(self.truth.timestamps_s[k]),
            r.image,
            r,
            share,
            self.exact_boxes(k, share),
            self.detections(k, share),
        )

    def __iter__(self) -> Iterator[SyntheticFrame]:
        for k in range(len(self)):
            yield self.frame(k)
