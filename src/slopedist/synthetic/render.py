"""Renderer of the synthetic hills: a textured image and the true depth map of every frame.

Convention:
    Camera frame x right, y down, z forward; pixel ``(row i, column j)`` is centred on image
    coordinates ``(x = j, y = i)``; ``R_world_cam`` camera-to-world, world frame of
    :mod:`~slopedist.synthetic.road`. Images are BGR ``H×W×3`` uint8; depth maps are
    float32 metres along the camera's z axis, ``+inf`` where a pixel sees the sky.

How it works (numpy + OpenCV, no GPU, one thread; speed in ``benchmarks/synthetic_hills.py``):

1. Visibility: every planar polygon of the world (:mod:`~slopedist.synthetic.world`)
   and of the target vehicles near the camera is projected, back faces culled, polygons crossing
   the near plane clipped, and its label drawn with ``cv2.fillConvexPoly`` into a label buffer
   in painter order (far to near along the road). The road is a height field seen from above,
   so drawing by plan distance is a correct occlusion order, crests included
   (:mod:`~slopedist.synthetic.visibility`).
2. Per polygon (:mod:`~slopedist.synthetic.label_tables`), its plane gives the depth
   and the texture coordinates in closed form:
   ``1/z = h_w·p``, ``t_x = (h_x·p)/(h_w·p)``, ``t_y = (h_y·p)/(h_w·p)`` with ``p = (x, y, 1)``
   (a homography per polygon). ``h_w·p``, ``h_x·p`` and ``h_y·p`` are affine in the pixel, so
   they are evaluated on a coarse grid (every ``CELL`` pixels) and interpolated bilinearly, which
   is exact inside one plane. A cell of the grid whose pixels and corners all see one polygon,
   or pieces of one smooth surface (the ground strips, the pieces of one wall) whose normals
   agree to ``TURN_TOLERANCE`` and whose extreme pieces agree at the corners to
   ``PLANE_TOLERANCE``, is drawn from the interpolation; every other cell (occlusion edges,
   crests, bumps, object boundaries, the sky's edge) is evaluated pixel by pixel from its own
   polygon's plane (``Renderer(interpolate=False)`` does that everywhere: the reference). Those
   pixels are written as the same homogeneous quantities (``1/z``, ``t·(1/z)``, the unrounded
   mip level, the colour terms) into the upsampled fields, so the division, the level's rounding
   and the atlas lookup run once over the whole frame. Depth is exact on single planes (float32
   rounding) and within about 1e-3 (relative) across the pieces of a surface; the depth map
   itself (cropped, the sky at ``+inf``) is made when first asked for
   (:attr:`Rendered.depth_m`).
3. Shading: one ``cv2.remap`` into a texture atlas (:mod:`~slopedist.synthetic.atlas`
   of the tiles of :mod:`~slopedist.synthetic.textures`: 1/f-noise textures with the
   lane markings, verge, windows, bands and the sky's gradient and clouds baked in,
   world-anchored, true mip levels chosen per pixel by the footprint), times the polygon's
   colour and sun shading with distance haze, and a fixed sensor-noise pattern shifted per
   frame; uint8 arithmetic.

The level of detail keeps a float field (a uint8 code would move level edges enough to change
the odometry's error on the rendered frames).

Everything is deterministic: textures from a fixed seed, the world from the scenario's seed.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import cv2
import numpy as np
from numpy.typing import NDArray

from slopedist.synthetic.atlas import MIP_LEVELS, atlas_xy_periods, texture_atlas
from slopedist.synthetic.label_tables import LabelTables, label_tables
from slopedist.synthetic.polygons import Material, Polygons
from slopedist.synthetic.textures import TEX_SIZE, U_REBASE_M, LaneLayout, Tex
from slopedist.synthetic.visibility import visible_polygons

FloatArray = NDArray[np.float64]
F32 = NDArray[np.float32]

VIEW_RANGE_M = 400.0
"""Static polygons farther ahead along the road than this are not drawn, metres."""
LOD_NEAR_M = 60.0
"""Ground strips and wall pieces are drawn at their fine level of detail up to this far ahead
of the camera along the road, coarse beyond, metres."""
HAZE_DISTANCE_M = 900.0
"""Distance at which haze hides 1 − 1/e of a surface's colour, metres."""
SENSOR_NOISE_GREY = 1.5
"""Standard deviation of the sensor noise, grey levels."""
CELL = 4
"""Side of the interpolation cells, pixels."""
TURN_TOLERANCE = 0.01
"""Largest angle between the normals of the pieces of one surface seen in a cell for the cell to
be interpolated, radians."""
PLANE_TOLERANCE = 2e-3
"""Largest relative disagreement of ``1/z`` between pieces of one surface at a cell's corners for
the cell to be interpolated (the interpolation error is a fraction of it)."""

# --- textures ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class Rendered:
    """One rendered frame.

    Attributes:
        image: BGR ``H×W×3`` uint8.
        labels: ``H×W`` uint16, the polygon seen at each pixel (0 = sky).
        label_owner: ``(n + 1,)`` index of the target vehicle each label belongs to (−1: none);
            the labels of the targets' faces are the highest, from ``first_vehicle_label``.
        depth_work: the depth on the renderer's working frame (image pixel ``(y, x)`` at
            ``(y + CELL/2, x + CELL/2)``; the sky's pixels arbitrary): :attr:`depth_m` is made
            from it when asked for.
    """

    image: NDArray[np.uint8]
    labels: NDArray[np.uint16]
    label_owner: NDArray[np.int16]
    first_vehicle_label: int
    depth_work: NDArray[np.float32] = field(repr=False)

    @functools.cached_property
    def depth_m(self) -> NDArray[np.float32]:
        """``H×W`` float32, metres along the camera z axis; ``+inf`` for sky (made on first
        access: callers that do not need depth do not pay for it)."""
        h, w = self.labels.shape
        o = CELL // 2
        depth = np.ascontiguousarray(self.depth_work[o : o + h, o : o + w])
        np.putmask(depth, self.labels == 0, np.float32(np.inf))
        return depth

    @functools.cached_property
    def owner(self) -> NDArray[np.int16]:
        """``H×W`` int16, index of the target vehicle seen at each pixel, −1 elsewhere."""
        return np.asarray(np.take(self.label_owner, self.labels), dtype=np.int16)

    def visible_pixels(self, n_targets: int) -> NDArray[np.int64]:
        """Number of pixels where each of ``n_targets`` targets is seen."""
        lab = self.labels[self.labels >= self.first_vehicle_label]
        owners = self.label_owner[lab]
        owners = owners[owners >= 0]
        return np.bincount(owners.astype(np.int64), minlength=n_targets)[:n_targets]


HAZE = np.array([0.88, 0.85, 0.82], np.float32)


@functools.lru_cache(maxsize=8)
def _haze_rows(n: int) -> F32:
    """``(n, 4)`` rows of the haze's BGR0 colour × 255."""
    return np.tile(np.float32(255.0) * np.append(HAZE, np.float32(0.0)), (n, 1))


def _haze_row(n: int) -> F32:
    """The haze's BGR0 colour × 255 repeated ``n`` times, ``(n, 4)`` (shared, read only)."""
    size = 1 << max(n - 1, 1).bit_length()  # few sizes cached
    return _haze_rows(max(size, n))[:n]


class Renderer:
    """Renders frames of one world (static polygons) seen by one camera.

    Args:
        static: the world's polygons in painter order (:func:`~slopedist.synthetic.
            world.static_world`).
        K: 3×3 intrinsics; width, height: image size in pixels.
        layout: the lanes (for the markings).
        seed: seed of the sensor noise pattern.
        interpolate: draw cells that see one surface from the coarse grid (False: every pixel
            from its own polygon's plane, the reference the interpolation is tested against).
    """

    def __init__(
        self,
        static: Polygons,
        K: FloatArray,
        width: int,
        height: int,
        layout: LaneLayout,
        seed: int = 0,
        interpolate: bool = True,
    ) -> None:
        self.interpolate = interpolate
        self.static = static
        self.K = np.asarray(K, dtype=float)
        self.K_inv = np.linalg.inv(self.K)
        self.width, self.height = int(width), int(height)
        self.layout = LaneLayout(
            float(layout.carriageway_half_m), int(layout.lanes), float(layout.lane_width_m)
        )
        ground = static.material == int(Material.GROUND)
        if ground.any():
            g = static.select(np.flatnonzero(ground))
            v = np.einsum("pkj,pj->pk", g.verts - g.origin[:, None], g.axis_v)
            ground_half = float(np.abs(v).max()) + 1.0
        else:
            ground_half = self.layout.carriageway_half_m + 1.0
        self._combined: Polygons | None = None
        self._atlas = texture_atlas(self.layout, round(ground_half, 3))
        # the coarse grid: sample (b, a) at image point (CELL a − ½, CELL b − ½); cell (b, a)
        # holds the pixels of rows CELL b … CELL b + CELL − 1 and the same columns
        w, h = self.width, self.height
        self._cells = (-(-h // CELL), -(-w // CELL))
        hc, wc = self._cells[0] + 1, self._cells[1] + 1
        self._xs = (CELL * np.arange(wc) - 0.5).astype(np.float32)
        self._ys = (CELL * np.arange(hc) - 0.5).astype(np.float32)
        self._sample_cols = np.minimum(CELL * np.arange(wc), w - 1)
        self._sample_rows = np.minimum(CELL * np.arange(hc), h - 1)
        self._log_rn_c = np.log2(self._ray_norm_over_f(self._xs[None, :], self._ys[:, None]))
        self._kernel = np.ones((CELL + 1, CELL + 1), np.uint8)
        self._corner_db = np.array([0, 0, 1, 1])[:, None]
        self._corner_da = np.array([0, 1, 0, 1])[:, None]
        off = np.arange(CELL, dtype=np.float32)
        self._cell_dy = np.repeat(off, CELL)
        self._cell_dx = np.tile(off, CELL)
        # per cell, its pixels' flat indices in the labels padded to whole cells (one more row
        # and column) and in the frame of the grid's ×CELL upsampling
        o = CELL // 2
        cy = (CELL * np.arange(self._cells[0]))[:, None, None] + self._cell_dy.astype(np.intp)
        cx = (CELL * np.arange(self._cells[1]))[None, :, None] + self._cell_dx.astype(np.intp)
        self._cell_labels = (cy * (CELL * self._cells[1] + 1) + cx).reshape(-1, CELL * CELL)
        self._cell_work = ((cy + o) * (CELL * wc) + cx + o).reshape(-1, CELL * CELL)
        ww = np.arange(CELL * wc, dtype=np.float32)[None, :] - o
        hw = np.arange(CELL * hc, dtype=np.float32)[:, None] - o
        self._log_rn_work = np.log2(self._ray_norm_over_f(ww, hw))
        rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, 0x0015E])
        noise = np.rint(
            rng.standard_normal((2 * h + 2 * CELL, 2 * w + 2 * CELL)) * SENSOR_NOISE_GREY
        )
        self._noise_pos = np.repeat(np.clip(noise, 0, 255).astype(np.uint8)[..., None], 3, axis=2)
        self._noise_neg = np.repeat(np.clip(-noise, 0, 255).astype(np.uint8)[..., None], 3, axis=2)

    def _ray_norm_over_f(self, x: F32, y: F32) -> F32:
        """``|r| / f`` of the rays through image points ``(x, y)``, ``r = K⁻¹ (x, y, 1)``."""
        K = self.K
        rx = (x - K[0, 2]) / K[0, 0]
        ry = (y - K[1, 2]) / K[1, 1]
        return np.asarray(np.sqrt(rx * rx + ry * ry + 1.0) / K[0, 0], dtype=np.float32)

    # -- polygon stage ---------------------------------------------------------------------------

    def _with_dynamic(self, dynamic: Polygons | None) -> Polygons:
        """The world's polygons followed by ``dynamic`` (rows kept between frames and
        overwritten: no copy of the world per frame)."""
        if dynamic is None or not len(dynamic):
            return self.static
        n = len(self.static)
        if self._combined is None or len(self._combined) != n + len(dynamic):
            self._combined = Polygons.concat([self.static, dynamic])
        else:
            for name in Polygons.__dataclass_fields__:
                getattr(self._combined, name)[n:] = getattr(dynamic, name)
        return self._combined

    # -- frame -----------------------------------------------------------------------------------

    def render(
        self,
        R_world_cam: FloatArray,
        centre_world: FloatArray,
        s_camera: float,
        dynamic: Polygons | None = None,
        frame: int = 0,
    ) -> Rendered:
        """Render one frame.

        Args:
            R_world_cam: camera-to-world rotation (3×3).
            centre_world: camera centre (3,), world frame.
            s_camera: plan distance of the camera along the road (selects nearby polygons).
            dynamic: polygons of the target vehicles (painter keys = plan distance of their
                rear), or None.
            frame: frame index (shifts the sensor-noise pattern).
        """
        R = np.asarray(R_world_cam, dtype=float)
        C = np.asarray(centre_world, dtype=float)
        st = self.static
        boundary = s_camera + LOD_NEAR_M
        detail = (
            (st.lod < 0)
            | ((st.lod == 0) & (st.lod_key < boundary))
            | ((st.lod == 1) & (st.lod_key >= boundary))
        )
        near = detail & (st.s_hi >= s_camera - 2.0) & (st.s_lo <= s_camera + VIEW_RANGE_M)
        idx = np.flatnonzero(near)
        polys = self._with_dynamic(dynamic)
        if len(polys) > len(st):  # the targets' faces, in the rows after the world's
            idx = np.concatenate([idx, np.arange(len(st), len(polys))])
        painter = idx[np.lexsort((polys.layer[idx], -polys.key[idx]))]
        visible, outlines = visible_polygons(
            polys, painter, R, C, self.K, (self.width, self.height)
        )
        visible = painter[visible]
        n = len(visible)
        if n >= np.iinfo(np.uint16).max:
            raise ValueError(f"{n} visible polygons: more than the label buffer holds")
        # labels: the pieces of one surface consecutive, the targets' faces last
        surface = polys.surface[visible]
        key = np.where(surface >= 0, surface, surface.max(initial=0) + 1 + np.arange(n))
        order = np.lexsort((np.arange(n), key, polys.owner[visible] >= 0))
        label = np.empty(n, np.int64)
        label[order] = np.arange(1, n + 1)
        labels = np.zeros((self.height, self.width), np.uint16)
        fill = cv2.fillConvexPoly
        for pts, value in zip(outlines, label.tolist(), strict=True):  # painter order
            fill(labels, pts, value, cv2.LINE_8, 4)
        ordered = polys.select(visible[order])
        u_base = U_REBASE_M * math.floor(s_camera / U_REBASE_M)
        tab = label_tables(ordered, key[order], R, C, self.K_inv, self._atlas, u_base)
        image, depth_work = self._shade(labels, tab, R, frame)
        owner = np.full(n + 1, -1, np.int16)
        owner[1:] = ordered.owner
        vehicles = np.flatnonzero(ordered.owner >= 0)
        first_vehicle = int(vehicles[0]) + 1 if vehicles.size else n + 1
        return Rendered(image, labels, owner, first_vehicle, depth_work)

    @staticmethod
    def _level(inv: F32, log_rn: F32, log_tpm: F32, log_c: F32) -> F32:
        """Mip level (unrounded) of surface points with ``1/z = inv`` (``≤ 0``: at infinity, the
        top level after clipping): log2 of the pixel footprint on the surface in texels, across
        the ray ``|r| z / f`` (no foreshortening) times the foreshortening along the surface's
        steepest direction ``z / |c|`` (``c``: the plane's distance) beyond the label's free
        foreshortening (1: the larger footprint, no aliasing); in logs, ``log2 z + log2(|r|/f)
        + log2(tpm) − MIP_BIAS + max(log2 z − log2(|c|·free), 0)`` (``LabelTables.per_label``)."""
        log_z = np.maximum(inv, np.float32(1e-30))
        np.log2(log_z, out=log_z)
        np.negative(log_z, out=log_z)
        fore = log_z - log_c
        np.maximum(fore, np.float32(0.0), out=fore)
        log_z += log_rn
        log_z += log_tpm
        log_z += fore
        return log_z

    def _sky(self, x: F32, y: F32, R: FloatArray) -> tuple[F32, F32]:
        """Texel coordinates in the sky's tile (level 0; ``t_x / TEX_SIZE``, ``t_y``) of image
        points ``(x, y)``: azimuth and elevation of their world directions."""
        K = self.K
        rx = (x - K[0, 2]) / K[0, 0]
        ry = (y - K[1, 2]) / K[1, 1]
        d = [R[i, 0] * rx + R[i, 1] * ry + R[i, 2] for i in range(3)]
        el = np.degrees(np.arctan2(d[2], np.hypot(d[0], d[1])))
        az = np.degrees(np.arctan2(d[1], d[0]))
        tx = az * (Tex.TEXELS_PER_M[Tex.SKY] / TEX_SIZE)
        ty = (el - Tex.V_MIN_M[Tex.SKY]) * Tex.TEXELS_PER_M_V[Tex.SKY] + self._atlas.y0[Tex.SKY]
        return tx.astype(np.float32), ty.astype(np.float32)

    @staticmethod
    def _colour_terms(inv: F32, tint: F32) -> tuple[NDArray[np.uint8], NDArray[np.uint8]]:
        """Per surface point (``inv = 1/z``, 2-D, ``≤ 0``: at infinity; ``tint``: ``inv.shape ×
        4`` BGR0 in [0, 1]): the factor of the texture (tint × share of the surface's colour
        through the haze, ``1 / (1 + z / HAZE_DISTANCE_M)``) and the haze added, ``inv.shape ×
        4`` BGRA uint8 (× 255, rounded)."""
        near = np.maximum(inv, np.float32(0.0))
        own = near + np.float32(1.0 / HAZE_DISTANCE_M)
        np.divide(near, own, out=own)
        own4 = np.asarray(cv2.merge([own] * 4))
        mult = cv2.convertScaleAbs(np.multiply(tint, own4, out=tint), alpha=255.0)
        np.subtract(np.float32(1.0), own4, out=own4)
        own4 *= _haze_row(own.size).reshape(own4.shape)
        add = cv2.convertScaleAbs(own4)
        return np.asarray(mult, np.uint8), np.asarray(add, np.uint8)

    def _shade(
        self, labels: NDArray[np.uint16], tab: LabelTables, R: FloatArray, frame: int
    ) -> tuple[NDArray[np.uint8], NDArray[np.float32]]:
        """Image and depth: cells seeing one surface from the coarse grid, the others pixel by
        pixel. Works on the frame of the grid's ×CELL upsampling (image pixel ``(y, x)`` at
        ``(y + CELL/2, x + CELL/2)``): the image is cropped at the end, the depth returned on
        that frame (the sky's pixels arbitrary, see :attr:`Rendered.depth_m`)."""
        h, w = self.height, self.width
        ny, nx = self._cells
        o = CELL // 2
        # 1. the coarse grid: homogeneous coordinates, mip level and colour terms per sample
        lab_c = labels[self._sample_rows][:, self._sample_cols].astype(np.intp)
        f = np.take(tab.per_label, lab_c, axis=1, mode="clip")
        xs, ys = self._xs[None, :], self._ys[:, None]
        inv_c = f[6] * xs + f[7] * ys + f[8]  # 0 for the sky (label 0)
        tx_c = f[0] * xs + f[1] * ys + f[2]
        ty_c = f[3] * xs + f[4] * ys + f[5]
        sky_c = lab_c == 0
        lev_c = self._level(inv_c, self._log_rn_c, f[9], f[10])
        mult_c, add_c = self._colour_terms(inv_c, np.take(tab.tint, lab_c, axis=0, mode="clip"))
        sky = np.flatnonzero(sky_c)
        if sky.size:  # the sky: its texel coordinates with w = 1, its colour as it is
            yy, xx = np.divmod(sky, sky_c.shape[1])
            tx, ty = self._sky(np.take(self._xs, xx), np.take(self._ys, yy), R)
            for grid, value in (
                (inv_c, 1.0),
                (tx_c, tx),
                (ty_c, ty),
                (lev_c, 0.0),
                (mult_c.view(np.uint32), 0xFFFFFFFF),
                (add_c.view(np.uint32), 0),
            ):
                np.put(grid, sky, value)
        np.clip(lev_c, 0.0, MIP_LEVELS - 1, out=lev_c)  # stays within the levels when interpolated
        # 2. cells: the labels seen in each (its pixels and corners), one surface or not
        padded = np.asarray(
            cv2.copyMakeBorder(
                labels, 0, CELL * ny + 1 - h, 0, CELL * nx + 1 - w, cv2.BORDER_REPLICATE
            ),
            dtype=np.uint16,
        )
        sub = (slice(0, CELL * ny, CELL), slice(0, CELL * nx, CELL))
        lo: NDArray[np.intp] = cv2.erode(padded, self._kernel, anchor=(0, 0))[sub].astype(np.intp)
        hi: NDArray[np.intp] = cv2.dilate(padded, self._kernel, anchor=(0, 0))[sub].astype(np.intp)
        good = np.take(tab.surface, lo, mode="clip") == np.take(tab.surface, hi, mode="clip")
        # a corner beyond its plane's horizon (a sliver of a far or edge-on polygon): exact
        beyond = (inv_c <= 0) & ~sky_c
        good &= ~(beyond[:-1, :-1] | beyond[:-1, 1:] | beyond[1:, :-1] | beyond[1:, 1:])
        self._check_pieces(good, lo, hi, inv_c, tab)
        if not self.interpolate:
            good[:] = False
        # 3. every pixel's homogeneous quantities from the coarse grid (exact inside cells that
        # see one plane), 4. the other cells' pixels from their own polygon's plane
        fields = self._interpolated(inv_c, tx_c, ty_c, lev_c, mult_c, add_c)
        cb, ca = np.nonzero(~good)
        if cb.size:
            self._exact(cb, ca, padded, tab, R, fields)
        # 5. depth, atlas coordinates, texture, colour and sensor noise on the image's pixels
        crop = (slice(o, o + h), slice(o, o + w))
        depth, mapx, mapy, lev, mult, add = fields
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            np.reciprocal(depth, out=depth)
            mapx *= depth  # the sky: w = 1 (its depth set below)
            mapy *= depth
            level = np.asarray(cv2.convertScaleAbs(lev), np.uint8)  # rounded
            mapx, mapy = atlas_xy_periods(mapx, mapy, level)
        texel = cv2.remap(self._atlas.image, mapx[crop], mapy[crop], cv2.INTER_LINEAR)
        cv2.multiply(texel, mult[crop], dst=texel, scale=1.0 / 255.0)
        cv2.add(texel, add[crop], dst=texel)
        image = cv2.cvtColor(texel, cv2.COLOR_BGRA2BGR)
        oy, ox = (frame * 7919) % h, (frame * 104729) % w
        cv2.add(image, self._noise_pos[oy : oy + h, ox : ox + w], dst=image)
        cv2.subtract(image, self._noise_neg[oy : oy + h, ox : ox + w], dst=image)
        return np.asarray(image, dtype=np.uint8), depth

    def _check_pieces(
        self,
        good: NDArray[np.bool_],
        lo: NDArray[np.intp],
        hi: NDArray[np.intp],
        inv_c: F32,
        tab: LabelTables,
    ) -> None:
        """Cells seeing several pieces of one surface stay interpolated only where the pieces'
        normals agree to ``TURN_TOLERANCE`` and the planes of the farthest and nearest pieces
        (extreme labels) agree with ``1/z`` at the cell's corners to ``PLANE_TOLERANCE`` (no
        crease, no bump, no crest hiding a farther piece); ``good`` is updated in place."""
        multi = good & (lo != hi)
        # every piece between the extreme labels within TURN_TOLERANCE of the others (a bump
        # or a crest between two coplanar pieces is no plane)
        multi &= ~(
            np.take(tab.turn, hi, mode="clip") - np.take(tab.turn, lo, mode="clip") > TURN_TOLERANCE
        )
        good &= (lo == hi) | multi
        cell = np.flatnonzero(multi)  # flat indices into the cells
        if not cell.size:
            return
        wc = inv_c.shape[1]
        cb, ca = np.divmod(cell, multi.shape[1])
        db, da = self._corner_db, self._corner_da
        x = np.take(self._xs, ca + da, mode="clip")  # (4, m): the corners
        y = np.take(self._ys, cb + db, mode="clip")
        ref = np.take(inv_c, (cb + db) * wc + ca + da, mode="clip")
        tol = PLANE_TOLERANCE * np.abs(ref)
        ok = np.ones(cell.shape, bool)
        for lab in (lo, hi):
            p = np.take(tab.per_label[6:9], np.take(lab, cell, mode="clip"), axis=1, mode="clip")
            ok &= np.all(np.abs(p[0] * x + p[1] * y + p[2] - ref) <= tol, axis=0)
        np.put(good, cell[~ok], False)

    def _interpolated(
        self,
        inv_c: F32,
        tx_c: F32,
        ty_c: F32,
        lev_c: F32,
        mult_c: NDArray[np.uint8],
        add_c: NDArray[np.uint8],
    ) -> _Fields:
        """The grid's quantities at every pixel (bilinear, exact within a plane), on the
        upsampling's frame."""
        hc, wc = inv_c.shape
        size = (CELL * wc, CELL * hc)

        def up(a: NDArray) -> NDArray:
            return np.asarray(cv2.resize(a, size, interpolation=cv2.INTER_LINEAR))

        # (in cells drawn pixel by pixel afterwards the values may be anything)
        return _Fields(*(up(a) for a in (inv_c, tx_c, ty_c, lev_c, mult_c, add_c)))

    def _exact(
        self,
        cb: NDArray[np.intp],
        ca: NDArray[np.intp],
        padded: NDArray[np.uint16],
        tab: LabelTables,
        R: FloatArray,
        fields: _Fields,
    ) -> None:
        """The pixels of cells ``(cb, ca)`` from their own polygon's plane, written into
        ``fields`` (``padded``: the labels, padded to whole cells and one more row and
        column)."""
        cell = cb * self._cells[1] + ca
        lab = np.take(
            padded, np.take(self._cell_labels, cell, axis=0, mode="clip").ravel(), mode="clip"
        ).astype(np.intp)
        where = np.take(self._cell_work, cell, axis=0, mode="clip").ravel()
        x = ((CELL * ca).astype(np.float32)[:, None] + self._cell_dx).ravel()
        y = ((CELL * cb).astype(np.float32)[:, None] + self._cell_dy).ravel()
        f = np.take(tab.per_label, lab, axis=1, mode="clip")
        inv = f[6] * x
        inv += f[7] * y
        inv += f[8]
        # the sky (0), and pixels whose centre is beyond their polygon's horizon (the fill
        # reaches half a pixel past an outline): seen at infinity
        np.maximum(inv, np.float32(0.0), out=inv)
        tx = f[0] * x
        tx += f[1] * y
        tx += f[2]
        ty = f[3] * x
        ty += f[4] * y
        ty += f[5]
        lev = self._level(inv, np.take(self._log_rn_work, where, mode="clip"), f[9], f[10])
        tint = np.take(tab.tint, lab[None], axis=0, mode="clip")  # one row (OpenCV: fast)
        mult, add = self._colour_terms(inv[None], tint)
        mult, add = mult[0], add[0]
        sky = np.flatnonzero(lab == 0)
        if sky.size:
            inv[sky] = 1.0
            tx[sky], ty[sky] = self._sky(x[sky], y[sky], R)
            lev[sky] = 0.0
            mult[sky] = 255
            add[sky] = 0
        np.clip(lev, 0.0, MIP_LEVELS - 1, out=lev)
        for buffer, values in zip(fields, (inv, tx, ty, lev, mult, add), strict=True):
            out: NDArray[Any] = np.asarray(buffer)
            if out.ndim == 3:  # BGRA as one 32-bit word
                out, values = out.view(np.uint32), values.view(np.uint32)
            out.ravel()[where] = values.ravel()


class _Fields(NamedTuple):
    """Per pixel of the upsampling's frame: ``1/z`` (1/m; 1 for the sky), the level-0 texel
    coordinates times ``1/z`` (``t_x / TEX_SIZE``, ``t_y``), the mip level (unrounded, within the
    levels), and the colour terms (BGRA uint8): texture factor × 255 and haze added."""

    inv: F32
    tx: F32
    ty: F32
    level: F32
    mult: NDArray[np.uint8]
    add: NDArray[np.uint8]
