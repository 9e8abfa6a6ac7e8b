"""Renderer of the synthetic hills: a textured image and the true depth map of every frame.

Convention:
    Camera frame x right, y down, z forward; pixel ``(row i, column j)`` is centred on image
    coordinates ``(x = j, y = i)``; ``R_world_cam`` camera-to-world, world frame of
    :mod:`~slopedist.datasets.synthetic.road`. Images are BGR ``H×W×3`` uint8; depth maps are
    float32 metres along the camera's z axis, ``+inf`` where a pixel sees the sky.

How it works (numpy + OpenCV, no GPU):

1. Visibility: every planar polygon of the world (:mod:`~slopedist.datasets.synthetic.world`)
   and of the target vehicles near the camera is projected, back faces culled, polygons crossing
   the near plane clipped, and its index drawn with ``cv2.fillConvexPoly`` into an index buffer in
   painter order (far to near along the road). The road is a height field seen from above, so
   drawing by plan distance is a correct occlusion order, crests included.
2. Per pixel, the polygon's plane gives the exact depth and texture coordinates in closed form:
   ``1/z = h_w·p`` and ``u = (h_u·p)·z`` with ``p = (x, y, 1)`` and per-polygon 3-vectors
   (a homography per polygon), so no ray marching.
3. Shading: tileable 1/f-noise textures (asphalt, grass, façades, foliage, objects, vehicles,
   clouds), mip-mapped and sampled with one ``cv2.remap`` from an atlas; lane markings, windows
   and bands are procedural on the texture coordinates, anti-aliased by the pixel footprint; a
   sky gradient with clouds fixed to world directions; distance haze; a fixed sensor-noise
   pattern shifted per frame.

Everything is deterministic: textures from a fixed seed, the world from the scenario's seed.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from slopedist.datasets.synthetic.world import Layer, Material, Polygons

FloatArray = NDArray[np.float64]

NEAR_CLIP_M = 0.3
"""Polygons are clipped at this camera depth, metres."""
VIEW_RANGE_M = 400.0
"""Static polygons farther ahead along the road than this are not drawn, metres."""
LOD_NEAR_M = 60.0
"""Ground strips and wall pieces are drawn at their fine level of detail up to this far ahead
of the camera along the road, coarse beyond, metres."""
HAZE_DISTANCE_M = 900.0
"""Distance at which haze hides 1 − 1/e of a surface's colour, metres."""
SENSOR_NOISE_GREY = 1.5
"""Standard deviation of the sensor noise, grey levels."""

# --- textures ---------------------------------------------------------------------------------

TEX_SIZE = 512
TEX_PAD = 2
MIP_LEVELS = 6


class Tex:
    """Texture indices in the atlas and their scale (texels per metre)."""

    ASPHALT, GRASS, FACADE, FOLIAGE, OBJECT, VEHICLE, CLOUD = range(7)
    COUNT = 7
    TEXELS_PER_M = np.array([64.0, 32.0, 16.0, 24.0, 32.0, 32.0, TEX_SIZE / 90.0],
                            dtype=np.float32)
    """Texels per metre (per degree of azimuth/elevation for clouds: four tiles round the sky)."""


MATERIAL_TEXTURE = {
    Material.SKY: Tex.CLOUD, Material.GROUND: Tex.ASPHALT, Material.BUILDING: Tex.FACADE,
    Material.TREES: Tex.FOLIAGE, Material.POST: Tex.OBJECT, Material.OBJECT: Tex.OBJECT,
    Material.VEHICLE: Tex.VEHICLE,
}


def _fft_noise(rng: np.random.Generator, beta: float, n: int = TEX_SIZE) -> FloatArray:
    """Periodic noise with power spectrum ∝ ``k^−β``, zero mean, unit standard deviation."""
    spec = np.fft.rfft2(rng.standard_normal((n, n)))
    ky = np.fft.fftfreq(n)[:, None]
    kx = np.fft.rfftfreq(n)[None, :]
    k = np.hypot(kx, ky)
    k[0, 0] = 1.0
    spec *= k ** (-beta / 2.0)
    spec[0, 0] = 0.0
    out = np.fft.irfft2(spec, s=(n, n))
    return np.asarray(out / out.std())


def _fft_blur(img: FloatArray, sigma: float) -> FloatArray:
    """Periodic Gaussian blur (σ in texels)."""
    if sigma <= 0:
        return img
    n = img.shape[0]
    ky = np.fft.fftfreq(n)[:, None]
    kx = np.fft.rfftfreq(n)[None, :]
    g = np.exp(-2.0 * (np.pi * sigma) ** 2 * (kx**2 + ky**2))
    return np.asarray(np.fft.irfft2(np.fft.rfft2(img) * g, s=img.shape))


def _base_textures(seed: int = 20240) -> list[FloatArray]:
    """Grey textures in [0, 1], one per :class:`Tex` index."""
    rng = np.random.default_rng(seed)
    n = TEX_SIZE
    speckle = (rng.random((n, n)) < 0.04) * rng.choice([-1.0, 1.0], (n, n))
    asphalt = (0.50 + 0.10 * _fft_noise(rng, 1.0) + 0.06 * _fft_noise(rng, 3.0)
               + 0.22 * _fft_blur(speckle, 0.7))
    grass = 0.50 + 0.20 * _fft_noise(rng, 1.4) + 0.08 * _fft_noise(rng, 3.0)
    facade = 0.62 + 0.06 * _fft_noise(rng, 1.2) + 0.06 * _fft_noise(rng, 3.0)
    leaves = _fft_noise(rng, 1.6)
    foliage = 0.30 + 0.45 / (1.0 + np.exp(-2.5 * leaves)) + 0.05 * _fft_noise(rng, 0.8)
    obj = 0.55 + 0.14 * _fft_noise(rng, 1.3)
    vehicle = 0.85 + 0.03 * _fft_noise(rng, 2.5)
    cloud = _fft_noise(rng, 3.2)
    cloud = 0.5 + 0.5 * np.tanh(1.5 * (cloud - 0.3))
    return [np.clip(t, 0.0, 1.0) for t in (asphalt, grass, facade, foliage, obj, vehicle, cloud)]


@functools.lru_cache(maxsize=1)
def texture_atlas() -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.float32]]:
    """The mip-mapped texture atlas (float32 grey) and the pixel origin of each (texture,
    level) tile: ``(atlas, x0 (COUNT, LEVELS), y0 (COUNT, LEVELS))``. Tiles carry ``TEX_PAD``
    texels of wrapped border so bilinear sampling is seamless."""
    n, pad = TEX_SIZE, TEX_PAD
    tile = n + 2 * pad
    atlas = np.zeros((Tex.COUNT * tile, MIP_LEVELS * tile), np.float32)
    x0 = np.zeros((Tex.COUNT, MIP_LEVELS), np.float32)
    y0 = np.zeros((Tex.COUNT, MIP_LEVELS), np.float32)
    for t, base in enumerate(_base_textures()):
        for lev in range(MIP_LEVELS):
            img = _fft_blur(base, 0.0 if lev == 0 else 0.6 * 2.0 ** (lev - 1))
            padded = np.pad(img, pad, mode="wrap")
            r, c = t * tile, lev * tile
            atlas[r:r + tile, c:c + tile] = padded
            x0[t, lev], y0[t, lev] = c + pad, r + pad
    return atlas, x0, y0


# --- the renderer -----------------------------------------------------------------------------


@dataclass(frozen=True)
class Rendered:
    """One rendered frame.

    Attributes:
        image: BGR ``H×W×3`` uint8.
        depth_m: ``H×W`` float32, metres along the camera z axis; ``+inf`` for sky.
        owner: ``H×W`` int16, index of the target vehicle seen at each pixel, −1 elsewhere.
    """

    image: NDArray[np.uint8]
    depth_m: NDArray[np.float32]
    owner: NDArray[np.int16]

    def visible_pixels(self, n_targets: int) -> NDArray[np.int64]:
        """Number of pixels where each of ``n_targets`` targets is seen."""
        o = self.owner[self.owner >= 0]
        return np.bincount(o.astype(np.int64), minlength=n_targets)[:n_targets]


BAND_ROWS = 32
"""Rows shaded together (small enough for the per-pixel arrays to stay in cache)."""


@dataclass(frozen=True)
class _FrameTables:
    """Per-polygon tables of one frame (row 0 = sky): the 9 pixel functionals, |plane
    distance|, material, tint (BGR), and the camera-to-world rotation as float32."""

    functionals: NDArray[np.float32]
    plane_c: NDArray[np.float32]
    material: NDArray[np.int32]
    tint: NDArray[np.float32]
    R_world_cam: NDArray[np.float32]


SUN_DIRECTION = np.array([0.35, -0.45, 0.82]) / np.linalg.norm([0.35, -0.45, 0.82])
"""Unit vector towards the sun, world frame (for face shading)."""
SKY_HORIZON = np.array([0.93, 0.88, 0.84], np.float32)
SKY_ZENITH = np.array([0.80, 0.55, 0.33], np.float32)
HAZE = np.array([0.88, 0.85, 0.82], np.float32)
MARKING_WHITE = 0.93
ASPHALT_TINT = np.array([0.62, 0.62, 0.64], np.float32)
GRASS_TINT = np.array([0.30, 0.55, 0.45], np.float32)
DASH_M, GAP_M = 3.0, 6.0
"""Lane separators: 3 m dashes with 6 m gaps."""
LINE_HALF_WIDTH_M = 0.075


def _coverage(dist: NDArray[np.float32], half_width: float,
              footprint: NDArray[np.float32]) -> NDArray[np.float32]:
    """Anti-aliased coverage of a stripe of ``half_width`` at distance ``dist`` from its axis,
    for pixels of footprint ``footprint`` (same units)."""
    return np.asarray(np.clip((half_width - dist) / np.maximum(footprint, 1e-4) + 0.5, 0.0, 1.0))


def _clip_halfplane(poly: FloatArray, axis: int, bound: float, keep_above: bool) -> FloatArray:
    """Sutherland–Hodgman: keep the part of polygon ``(n, d)`` with ``x[axis] ≥ bound``
    (``keep_above``) or ``≤ bound``."""
    out = []
    n = poly.shape[0]
    sign = 1.0 if keep_above else -1.0
    for i in range(n):
        a, b = poly[i], poly[(i + 1) % n]
        da, db = sign * (a[axis] - bound), sign * (b[axis] - bound)
        if da >= 0:
            out.append(a)
        if (da >= 0) != (db >= 0):
            out.append(a + (da / (da - db)) * (b - a))
    return np.asarray(out).reshape(-1, poly.shape[1])


def clip_polygon_near(poly_cam: FloatArray, near: float = NEAR_CLIP_M) -> FloatArray:
    """Clip one polygon ``(n, 3)`` (camera frame) to ``z ≥ near``."""
    return _clip_halfplane(poly_cam, 2, near, True)


def clip_polygon_rect(poly_px: FloatArray, x0: float, y0: float, x1: float, y1: float
                      ) -> FloatArray:
    """Clip one polygon ``(n, 2)`` (pixels) to the rectangle ``[x0, x1] × [y0, y1]``."""
    for axis, bound, above in ((0, x0, True), (0, x1, False), (1, y0, True), (1, y1, False)):
        if poly_px.shape[0] < 3:
            break
        poly_px = _clip_halfplane(poly_px, axis, bound, above)
    return poly_px


FILL_LIMIT_PX = 8000.0
"""Outlines reaching farther than this from the image are clipped to it before filling
(``cv2.fillConvexPoly`` works in 16.16 fixed point and overflows beyond ±32768 pixels)."""


class Renderer:
    """Renders frames of one world (static polygons) seen by one camera.

    Args:
        static: the world's polygons in painter order (:func:`~slopedist.datasets.synthetic.
            world.static_world`).
        K: 3×3 intrinsics; width, height: image size in pixels.
        carriageway_half_m: half-width of the asphalt; lanes, lane_width_m: lane layout
            (for the markings).
        seed: seed of the sensor noise pattern.
    """

    def __init__(self, static: Polygons, K: FloatArray, width: int, height: int,
                 carriageway_half_m: float, lanes: int, lane_width_m: float,
                 seed: int = 0) -> None:
        self.static = static
        self.K = np.asarray(K, dtype=float)
        self.K_inv_T = np.linalg.inv(self.K).T
        self.width, self.height = int(width), int(height)
        self.half = float(carriageway_half_m)
        self.lanes = int(lanes)
        self.lane_width = float(lane_width_m)
        jj, ii = np.meshgrid(np.arange(width, dtype=np.float32),
                             np.arange(height, dtype=np.float32))
        self._xf, self._yf = jj.ravel(), ii.ravel()
        self._rays = np.stack([(jj - K[0, 2]) / K[0, 0], (ii - K[1, 2]) / K[1, 1],
                               np.ones_like(jj)], axis=-1).reshape(-1, 3).astype(np.float32)
        self._ray_norm_over_f = (np.linalg.norm(self._rays, axis=1) / K[0, 0]).astype(np.float32)
        self._plane_c = np.zeros(0)
        rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, 0x0015E])
        self._noise = (rng.standard_normal((2 * height, 2 * width)) * SENSOR_NOISE_GREY
                       + 0.5).astype(np.float32)  # + 0.5: rounding when cast to uint8
        self._atlas, self._tile_x0, self._tile_y0 = texture_atlas()
        self._mat_tex = np.array([MATERIAL_TEXTURE[Material(m)] for m in range(len(Material))],
                                 dtype=np.int32)

    # -- polygon stage ---------------------------------------------------------------------------

    def _visible_polygons(self, polys: Polygons, R_wc: FloatArray, C_w: FloatArray
                          ) -> tuple[Polygons, list[NDArray[np.int32]]]:
        """Cull, clip and project; returns the kept polygons and their integer pixel outlines
        (``cv2.fillConvexPoly`` coordinates with 4 fractional bits)."""
        to_cam = polys.verts[:, 0] - C_w
        facing = polys.two_sided | (np.einsum("pi,pi->p", -to_cam, polys.normal) > 1e-9)
        polys = polys.select(np.flatnonzero(facing))
        vc = np.einsum("ji,pkj->pki", R_wc, polys.verts - C_w)
        z = vc[..., 2]
        all_in = np.all(z >= NEAR_CLIP_M, axis=1)
        any_in = np.any(z >= NEAR_CLIP_M, axis=1)
        K = self.K
        outlines: list[NDArray[np.int32] | None] = [None] * len(polys)
        zz = np.where(all_in[:, None], z, 1.0)
        px = np.stack([K[0, 0] * vc[..., 0] / zz + K[0, 2], K[1, 1] * vc[..., 1] / zz + K[1, 2]],
                      axis=-1)
        w, h = self.width, self.height
        onscreen = ((px[..., 0].max(1) >= -1) & (px[..., 0].min(1) <= w) & (px[..., 1].max(1) >= -1)
                    & (px[..., 1].min(1) <= h))
        lim = FILL_LIMIT_PX
        huge = np.any((px < -lim) | (px > np.array([w + lim, h + lim])), axis=(1, 2))
        fixed = np.round(np.where(huge[:, None, None], 0.0, px) * 16.0).astype(np.int32)
        keep = []
        for p in np.flatnonzero(all_in & onscreen & ~huge):
            outlines[p] = fixed[p]
            keep.append(p)
        for p in np.flatnonzero(any_in & ~(all_in & onscreen & ~huge)):
            if all_in[p]:
                q = px[p]
            else:
                poly = clip_polygon_near(vc[p])
                if poly.shape[0] < 3:
                    continue
                q = np.stack([K[0, 0] * poly[:, 0] / poly[:, 2] + K[0, 2],
                              K[1, 1] * poly[:, 1] / poly[:, 2] + K[1, 2]], axis=-1)
            q = clip_polygon_rect(q, -4.0, -4.0, w + 4.0, h + 4.0)
            if q.shape[0] < 3:
                continue
            outlines[p] = np.round(q * 16.0).astype(np.int32)
            keep.append(p)
        keep_arr = np.sort(np.asarray(keep, dtype=np.int64))  # painter order is index order
        return polys.select(keep_arr), [o for o in (outlines[p] for p in keep_arr) if o is not None]

    def _pixel_functionals(self, polys: Polygons, R_wc: FloatArray, C_w: FloatArray
                           ) -> NDArray[np.float32]:
        """Per polygon, the 9 coefficients ``(h_u, h_v, h_w)``: ``1/z = h_w·p``,
        ``u = (h_u·p)/(h_w·p)``, ``v = (h_v·p)/(h_w·p)`` for pixels ``p = (x, y, 1)``."""
        K_inv = self.K_inv_T.T
        n_c = polys.normal @ R_wc  # rows: (R_wcᵀ n)ᵀ, the normals in the camera frame
        x0_c = (polys.verts[:, 0] - C_w) @ R_wc
        o_c = (polys.origin - C_w) @ R_wc
        c = np.einsum("pi,pi->p", n_c, x0_c)  # plane: n_c · X = c
        c = np.where(np.abs(c) < 1e-9, 1e-9, c)
        self._plane_c = c
        h_w = (n_c @ K_inv) / c[:, None]  # rows: (K⁻ᵀ n / c)ᵀ
        rows = []
        for axis, off in ((polys.axis_u, polys.u0), (polys.axis_v, np.zeros(len(polys)))):
            a_c = axis @ R_wc
            k = off - np.einsum("pi,pi->p", a_c, o_c)
            rows.append(a_c @ K_inv + k[:, None] * h_w)
        rows.append(h_w)
        table = np.zeros((len(polys) + 1, 9), np.float32)
        table[1:] = np.concatenate(rows, axis=1)
        return table

    # -- frame -----------------------------------------------------------------------------------

    def render(self, R_world_cam: FloatArray, centre_world: FloatArray, s_camera: float,
               dynamic: Polygons | None = None, frame: int = 0) -> Rendered:
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
        detail = (st.lod < 0) | ((st.lod == 0) & (st.lod_key < boundary)) | (
            (st.lod == 1) & (st.lod_key >= boundary))
        near = detail & (st.s_hi >= s_camera - 2.0) & (st.s_lo <= s_camera + VIEW_RANGE_M)
        polys = st.select(np.flatnonzero(near))
        if dynamic is not None and len(dynamic):
            polys = Polygons.concat([polys, dynamic])
            polys = polys.select(np.lexsort((polys.layer, -polys.key)))
        polys, outlines = self._visible_polygons(polys, R, C)
        ids = np.zeros((self.height, self.width), np.int32)
        for k, pts in enumerate(outlines):
            cv2.fillConvexPoly(ids, pts, k + 1, cv2.LINE_8, 4)
        return self._shade(ids, polys, R, C, frame)

    def _shade(self, ids: NDArray[np.int32], polys: Polygons, R: FloatArray, C: FloatArray,
               frame: int) -> Rendered:
        """Per-pixel depth, texture and colour, in bands of rows (the arrays of a band stay in
        the processor's cache)."""
        h, w = self.height, self.width
        f32 = np.float32
        n = len(polys) + 1
        plane_c = np.ones(n, f32)
        mat_table = np.zeros(n, np.int32)
        shade = 0.62 + 0.38 * np.clip(polys.normal @ SUN_DIRECTION, 0.0, 1.0)
        tint = np.ones((n, 3), f32)
        owner_table = np.full(n, -1, np.int16)
        tables = _FrameTables(self._pixel_functionals(polys, R, C), plane_c, mat_table, tint,
                              R.astype(f32))
        plane_c[1:] = np.abs(self._plane_c)
        mat_table[1:] = polys.material
        tint[1:] = polys.colour * shade[:, None]
        tint[1:][polys.material == int(Material.GROUND)] = ASPHALT_TINT
        owner_table[1:] = polys.owner
        image = np.empty((h, w, 3), np.uint8)
        depth = np.empty((h, w), f32)
        oy, ox = (frame * 7919) % h, (frame * 104729) % w
        for r0 in range(0, h, BAND_ROWS):
            r1 = min(h, r0 + BAND_ROWS)
            channels, z = self._shade_band(ids[r0:r1].ravel().astype(np.intp),
                                           slice(r0 * w, r1 * w), tables)
            noise = self._noise[oy + r0:oy + r1, ox:ox + w].ravel()
            for c, ch in enumerate(channels):
                ch *= 255.0
                ch += noise
                np.clip(ch, 0, 255, out=ch)
                image[r0:r1, :, c] = ch.reshape(r1 - r0, w)
            depth[r0:r1] = z.reshape(r1 - r0, w)
        return Rendered(image, depth, np.take(owner_table, ids))

    def _shade_band(self, flat: NDArray[np.intp], pix: slice, tab: _FrameTables
                    ) -> tuple[list[NDArray[np.float32]], NDArray[np.float32]]:
        """Colour (three ``(N,)`` channels B, G, R in [0, 1]) and depth of the pixels ``pix``
        with polygon indices ``flat`` (0 = sky)."""
        f32 = np.float32
        x, y = self._xf[pix], self._yf[pix]
        col = np.take(tab.functionals, flat, axis=0)  # (N, 9)
        inv_z = col[:, 6] * x
        inv_z += col[:, 7] * y
        inv_z += col[:, 8]
        sky = flat == 0
        inv_z[sky] = 1.0
        z = 1.0 / inv_z
        U = col[:, 0] * x
        U += col[:, 1] * y
        U += col[:, 2]
        U *= z
        V = col[:, 3] * x
        V += col[:, 4] * y
        V += col[:, 5]
        V *= z
        del col
        # pixel footprint on the surface (metres): across (no foreshortening) and along the
        # steepest direction (foreshortened by the plane's obliquity): |r| z / f and
        # |r| z² / (f |c|), with c the plane's distance from the camera centre
        across = z * self._ray_norm_over_f[pix]
        along = across * z
        along /= np.maximum(np.take(tab.plane_c, flat), 1e-3)
        np.maximum(along, across, out=along)
        # materials and textures per pixel
        mat = np.take(tab.material, flat)
        tex = np.take(self._mat_tex, mat)
        ground = mat == int(Material.GROUND)
        verge = ground & (np.abs(V) > self.half)
        verge_idx = np.flatnonzero(verge)
        tex[verge_idx] = Tex.GRASS
        # sky: texture coordinates (degrees) from the world direction of each ray
        sky_idx = np.flatnonzero(sky)
        rays = self._rays[pix]
        rx, ry = rays[sky_idx, 0], rays[sky_idx, 1]
        Rf = tab.R_world_cam
        dx = Rf[0, 0] * rx + Rf[0, 1] * ry + Rf[0, 2]
        dy = Rf[1, 0] * rx + Rf[1, 1] * ry + Rf[1, 2]
        dz = Rf[2, 0] * rx + Rf[2, 1] * ry + Rf[2, 2]
        el = np.degrees(np.arctan2(dz, np.hypot(dx, dy)))
        az = np.degrees(np.arctan2(dy, dx))
        U[sky_idx] = az * 2.0
        V[sky_idx] = el * 3.0
        along[sky_idx] = 0.0
        z[sky_idx] = np.inf
        # mip level from the footprint, then one bilinear lookup in the atlas
        tpm = np.take(Tex.TEXELS_PER_M, tex)
        lev = np.log2(np.maximum(along * tpm, 1e-6))
        np.clip(np.rint(lev, out=lev), 0, MIP_LEVELS - 1, out=lev)
        tile = tex * np.int32(MIP_LEVELS) + lev.astype(np.int32)
        n = f32(TEX_SIZE)
        su = U * tpm
        sv = V * tpm
        mapx = su - n * np.floor(su / n)
        mapx += np.take(self._tile_x0.ravel(), tile)
        mapy = sv - n * np.floor(sv / n)
        mapy += np.take(self._tile_y0.ravel(), tile)
        grey: NDArray[np.float32] = np.asarray(cv2.remap(
            self._atlas, mapx.reshape(-1, self.width), mapy.reshape(-1, self.width),
            cv2.INTER_LINEAR),
            dtype=np.float32).ravel()
        # procedural details on the grey level (markings, windows, bands)
        self._ground_details(grey, U, V, across, along, ground, verge)
        self._structure_details(grey, mat, U, V, along)
        # colour, channel by channel: tint × grey, haze, sky
        cloud = grey[sky_idx]
        fog = 1.0 / (1.0 + z * f32(1.0 / HAZE_DISTANCE_M))  # share of the surface's own colour
        grey *= fog
        haze = 1.0 - fog
        t_el = np.clip(el / 25.0, 0.0, 1.0)
        cover = np.clip((cloud - 0.45) * 2.5, 0.0, 1.0)
        channels = []
        for c in range(3):
            ch = np.take(tab.tint[:, c], flat)
            ch[verge_idx] = GRASS_TINT[c]
            ch *= grey
            ch += haze * HAZE[c]
            sky_c = SKY_HORIZON[c] + (SKY_ZENITH[c] - SKY_HORIZON[c]) * t_el
            ch[sky_idx] = sky_c + (0.97 - sky_c) * cover
            channels.append(ch)
        return channels, z

    def _ground_details(self, grey: NDArray[np.float32], U: NDArray[np.float32],
                        V: NDArray[np.float32], across: NDArray[np.float32],
                        along: NDArray[np.float32], ground: NDArray[np.bool_],
                        verge: NDArray[np.bool_]) -> None:
        """Lane markings on the asphalt, blended into the grey level (in place)."""
        road = np.flatnonzero(ground & ~verge)
        v = V[road]
        lw = self.lane_width
        near_line = np.abs(np.abs(v) - (self.half - 0.25)) < 0.3
        if self.lanes > 1:
            off = np.mod(v + self.half, lw)
            near_line |= (np.minimum(off, lw - off) < 0.3)
        road = road[near_line]
        u, v = U[road], V[road]
        f_u, f_v = along[road], across[road]
        cover = _coverage(np.abs(np.abs(v) - (self.half - 0.25)), LINE_HALF_WIDTH_M, f_v)
        if self.lanes > 1:
            k = np.clip(np.rint((v + self.half) / self.lane_width), 1, self.lanes - 1)
            d = np.abs(v + self.half - k * self.lane_width)
            period = DASH_M + GAP_M
            phase = u - period * np.floor(u / period)
            inside = np.minimum(phase, DASH_M - phase)  # > 0 within a dash
            dash = _coverage(-inside, 0.0, f_u)
            np.maximum(cover, _coverage(d, LINE_HALF_WIDTH_M, f_v) * dash, out=cover)
        g = grey[road]
        white = MARKING_WHITE / ASPHALT_TINT.mean() * (0.9 + 0.1 * g)
        grey[road] = g + (white - g) * cover

    def _structure_details(self, grey: NDArray[np.float32], mat: NDArray[np.int32],
                           U: NDArray[np.float32], V: NDArray[np.float32],
                           along: NDArray[np.float32]) -> None:
        """Windows on buildings, bands on posts and vehicles (in place, grey level)."""
        b = np.flatnonzero(mat == int(Material.BUILDING))
        if b.size:
            u, v, fb = U[b], V[b], along[b]
            pu = np.abs(u - 3.2 * np.floor(u / 3.2) - 1.6)
            pv = np.abs(v - 3.0 * np.floor(v / 3.0) - 1.7)
            win = _coverage(pu, 0.65, fb) * _coverage(pv, 0.6, fb) * (v > 1.0)
            grey[b] *= 1.0 - 0.65 * win
        p = np.flatnonzero(mat == int(Material.POST))
        if p.size:
            grey[p] *= 1.0 - 0.85 * _coverage(np.abs(V[p] - 0.75), 0.1, along[p])
        veh = np.flatnonzero(mat == int(Material.VEHICLE))
        if veh.size:
            v, fv = V[veh], along[veh]
            dark = np.maximum(_coverage(np.abs(v - 1.08), 0.22, fv),
                              _coverage(np.abs(v - 0.35), 0.12, fv) * 0.8)
            grey[veh] *= 1.0 - 0.6 * dark


def vehicle_polygons(corners_world: FloatArray, colours_bgr: FloatArray, s_rear: FloatArray,
                     s_front: FloatArray, owners: NDArray[np.int64]) -> Polygons:
    """Faces of target boxes from their 8 corners ``(M, 8, 3)`` (order of
    :data:`~slopedist.datasets.synthetic.vehicles.BOX_CORNERS_UNIT`); colours BGR in [0, 1]."""
    c = corners_world
    fwd = c[:, 2] - c[:, 0]
    lft = c[:, 1] - c[:, 0]
    up = c[:, 4] - c[:, 0]
    fwd, lft, up = (a / np.linalg.norm(a, axis=1, keepdims=True) for a in (fwd, lft, up))
    faces = [((0, 1, 5, 4), -fwd, lft), ((3, 2, 6, 7), fwd, -lft), ((2, 0, 4, 6), -lft, -fwd),
             ((1, 3, 7, 5), lft, fwd), ((4, 5, 7, 6), up, lft)]
    m = c.shape[0]
    parts = []
    for idx, normal, axis_u in faces:
        v = c[:, list(idx)]
        parts.append(Polygons(
            verts=v, normal=normal, origin=v[:, 0], axis_u=axis_u, axis_v=up,
            u0=np.zeros(m), key=s_rear.copy(), layer=np.full(m, int(Layer.VEHICLE)),
            s_lo=s_rear.copy(), s_hi=s_front.copy(), material=np.full(m, int(Material.VEHICLE)),
            colour=colours_bgr.copy(), owner=owners.astype(np.int64),
            two_sided=np.zeros(m, bool), lod=np.full(m, -1, np.int8), lod_key=np.zeros(m),
        ))
    return Polygons.concat(parts)
