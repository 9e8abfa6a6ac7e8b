"""Renderer of the synthetic hills: a textured image and the true depth map of every frame.

Convention:
    Camera frame x right, y down, z forward; pixel ``(row i, column j)`` is centred on image
    coordinates ``(x = j, y = i)``; ``R_world_cam`` camera-to-world, world frame of
    :mod:`~slopedist.datasets.synthetic.road`. Images are BGR ``H×W×3`` uint8; depth maps are
    float32 metres along the camera's z axis, ``+inf`` where a pixel sees the sky.

How it works (numpy + OpenCV, no GPU, one thread; speed in ``benchmarks/synthetic_hills.py``):

1. Visibility: every planar polygon of the world (:mod:`~slopedist.datasets.synthetic.world`)
   and of the target vehicles near the camera is projected, back faces culled, polygons crossing
   the near plane clipped, and its label drawn with ``cv2.fillConvexPoly`` into a label buffer
   in painter order (far to near along the road). The road is a height field seen from above,
   so drawing by plan distance is a correct occlusion order, crests included.
2. Per polygon, its plane gives the depth and the texture coordinates in closed form:
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
3. Shading: one ``cv2.remap`` into a texture atlas (1/f-noise textures with the lane markings,
   verge, windows, bands and the sky's gradient and clouds baked in, world-anchored, true mip
   levels chosen per pixel by the footprint), times the polygon's colour and sun shading with
   distance haze, and a fixed sensor-noise pattern shifted per frame; uint8 arithmetic.

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

from slopedist.datasets.synthetic.world import Layer, Material, Polygons

FloatArray = NDArray[np.float64]
F32 = NDArray[np.float32]

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
CELL = 4
"""Side of the interpolation cells, pixels."""
TURN_TOLERANCE = 0.01
"""Largest angle between the normals of the pieces of one surface seen in a cell for the cell to
be interpolated, radians."""
PLANE_TOLERANCE = 2e-3
"""Largest relative disagreement of ``1/z`` between pieces of one surface at a cell's corners for
the cell to be interpolated (the interpolation error is a fraction of it)."""

# --- textures ---------------------------------------------------------------------------------

TEX_SIZE = 512
"""Period of every texture along its ``u`` axis (the atlas's width), texels."""
MIP_LEVELS = 6
MIP_BIAS = 0.5
"""Levels are chosen this much sharper than the footprint says."""
ROAD_FORESHORTENING_FREE = 16.0
"""The road's mip level counts only its foreshortening beyond this factor: seen ahead at a
grazing angle, its lane markings and texture stay sharp across the road (somewhat aliased along
it); beyond a crest, at the most grazing angles, it blurs."""
MIP_DECIMATION = (1, 2, 4, 8, 16, 32)
"""Level ``l`` keeps every ``MIP_DECIMATION[l]``-th texel of its blurred tile (neighbouring
pixels stay near in memory)."""
TILE_PAD = 2
"""Rows repeated above and below every tile of the atlas (bilinear sampling at its edges)."""


class Tex:
    """Textures of the atlas: their scale and the range of ``v`` each tile covers."""

    ROAD, FACADE, FOLIAGE, OBJECT, POST, VEHICLE, SKY = range(7)
    COUNT = 7
    TEXELS_PER_M = np.array([64.0, 16.0, 32.0, 32.0, 32.0, 32.0, TEX_SIZE / 45.0])
    """Texels per metre along ``u`` (the road's tile: one 8 m period of the lane dashes; the
    sky's: per degree of azimuth, eight tiles round the horizon). Every period along ``u``
    divides ``U_REBASE_M``."""
    TEXELS_PER_M_V = TEXELS_PER_M * np.array([1, 1, 1, 1, 1, 1, 1.5])
    """Texels per metre along ``v`` (the sky's: per degree of elevation)."""
    V_MIN_M = np.array([math.nan, -20.0, -20.0, -2.0, -2.0, -2.0, -683.0 / TEXELS_PER_M_V[6]])
    """``v`` of a tile's first row, metres (the road's tile spans the ground's width; the sky's
    starts 40° below the horizon)."""
    ROWS = (0, 1024, 1536, 256, 256, 256, 1707)
    """Rows of a tile (the road's from the ground's width; the sky's up to 60° elevation)."""


MATERIAL_TEXTURE = {
    Material.GROUND: Tex.ROAD,
    Material.BUILDING: Tex.FACADE,
    Material.TREES: Tex.FOLIAGE,
    Material.POST: Tex.POST,
    Material.OBJECT: Tex.OBJECT,
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


def _resampled(img: FloatArray, n: int = TEX_SIZE) -> FloatArray:
    """A periodic texture resampled to ``n × n`` (Fourier interpolation), standard deviation
    kept."""
    m = img.shape[0]
    spec = np.fft.fft2(img)
    out = np.zeros((n, n), complex)
    h = m // 2
    out[:h, :h], out[:h, -h:], out[-h:, :h], out[-h:, -h:] = (
        spec[:h, :h],
        spec[:h, -h:],
        spec[-h:, :h],
        spec[-h:, -h:],
    )
    res = np.fft.ifft2(out).real
    return np.asarray(res * (img.std() / res.std()))


def _fft_blur(img: FloatArray, sigma: float) -> FloatArray:
    """Periodic Gaussian blur (σ in texels)."""
    if sigma <= 0:
        return img
    n = img.shape[0]
    ky = np.fft.fftfreq(n)[:, None]
    kx = np.fft.rfftfreq(n)[None, :]
    g = np.exp(-2.0 * (np.pi * sigma) ** 2 * (kx**2 + ky**2))
    return np.asarray(np.fft.irfft2(np.fft.rfft2(img) * g, s=img.shape))


@functools.lru_cache(maxsize=1)
def _base_textures(seed: int = 20240) -> dict[str, FloatArray]:
    """Periodic grey textures (512×512) in [0, 1]."""
    rng = np.random.default_rng(seed)
    n = TEX_SIZE
    speckle = (rng.random((n, n)) < 0.04) * rng.choice([-1.0, 1.0], (n, n))
    asphalt = (
        0.50
        + 0.10 * _fft_noise(rng, 1.0)
        + 0.06 * _fft_noise(rng, 3.0)
        + 0.22 * _fft_blur(speckle, 0.7)
    )
    # grass, on the road's tile at 64 texels per metre, and foliage, at 32, keep the features
    # they have at 32 and 24: drawn on smaller tiles (their own streams) and resampled
    own = np.random.default_rng([seed, 1])
    grass = (
        0.50
        + 0.20 * _resampled(_fft_noise(own, 1.4, n // 2))
        + 0.08 * _resampled(_fft_noise(own, 3.0, n // 2))
    )
    _fft_noise(rng, 1.4), _fft_noise(rng, 3.0)  # the draws the other textures follow
    facade = 0.62 + 0.06 * _fft_noise(rng, 1.2) + 0.06 * _fft_noise(rng, 3.0)
    leaves = _resampled(_fft_noise(own, 1.6, 3 * n // 4))
    foliage = (
        0.30
        + 0.45 / (1.0 + np.exp(-2.5 * leaves))
        + 0.05 * _resampled(_fft_noise(own, 0.8, 3 * n // 4))
    )
    _fft_noise(rng, 1.6), _fft_noise(rng, 0.8)
    obj = 0.55 + 0.14 * _fft_noise(rng, 1.3)
    vehicle = 0.85 + 0.03 * _fft_noise(rng, 2.5)
    cloud = _fft_noise(rng, 3.2)
    cloud = 0.5 + 0.5 * np.tanh(1.5 * (cloud - 0.3))
    out = dict(
        asphalt=asphalt,
        grass=grass,
        facade=facade,
        foliage=foliage,
        object=obj,
        vehicle=vehicle,
        cloud=cloud,
    )
    return {k: np.clip(v, 0.0, 1.0) for k, v in out.items()}


def _coverage(
    dist: NDArray[np.floating], half_width: float, footprint: NDArray[np.floating] | float
) -> NDArray[np.floating]:
    """Anti-aliased coverage of a stripe of ``half_width`` at distance ``dist`` from its axis,
    for pixels (texels) of footprint ``footprint`` (same units)."""
    return np.asarray(np.clip((half_width - dist) / np.maximum(footprint, 1e-4) + 0.5, 0.0, 1.0))


def _gauss_kernel(sigma: float) -> FloatArray:
    if sigma <= 0:
        return np.ones((1, 1))
    r = math.ceil(3.0 * sigma)
    k = np.exp(-0.5 * (np.arange(-r, r + 1) / sigma) ** 2)
    return (k / k.sum())[:, None]


def _blur_wrap_x(img: FloatArray, sigma_x: float, sigma_y: float) -> FloatArray:
    """Gaussian blur, periodic along x (axis 1), mirrored at the first and last rows."""
    if sigma_x <= 0 and sigma_y <= 0:
        return img
    kx, ky = _gauss_kernel(sigma_x), _gauss_kernel(sigma_y)
    pad = kx.shape[0] // 2 + 1
    wide = np.concatenate([img[:, -pad:], img, img[:, :pad]], axis=1).astype(np.float32)
    out = cv2.sepFilter2D(
        wide, -1, kx.astype(np.float32), ky.astype(np.float32), borderType=cv2.BORDER_REFLECT
    )
    return np.asarray(out[:, pad:-pad], dtype=np.float64)


def _level_sigma(level: int) -> float:
    """Blur of mip level ``level``, texels of level 0."""
    return 0.0 if level == 0 else 0.6 * 2.0 ** (level - 1)


DASH_M, GAP_M = 3.0, 5.0
"""Lane separators: 3 m dashes with 5 m gaps (one period per road tile)."""
LINE_HALF_WIDTH_M = 0.075
MARKING_WHITE = 0.93
ASPHALT_TINT = np.array([0.62, 0.62, 0.64])
GRASS_TINT = np.array([0.30, 0.55, 0.45])


def _grey_tile(tex: int) -> FloatArray:
    """Grey tile of a wall or box texture, ``(ROWS, 512)`` in [0, 1], details baked in."""
    base = _base_textures()
    name = {
        Tex.FACADE: "facade",
        Tex.FOLIAGE: "foliage",
        Tex.OBJECT: "object",
        Tex.POST: "object",
        Tex.VEHICLE: "vehicle",
    }[tex]
    rows = Tex.ROWS[tex]
    g = np.tile(base[name], (-(-rows // TEX_SIZE), 1))[:rows].copy()
    tpm = float(Tex.TEXELS_PER_M[tex])
    u = (np.arange(TEX_SIZE) / tpm)[None, :]
    v = (Tex.V_MIN_M[tex] + np.arange(rows) / tpm)[:, None]
    fp = 1.0 / tpm
    if tex == Tex.FACADE:  # windows, 3.2 m apart, rows of 3 m from 1 m above the base
        pu = np.abs(u - 3.2 * np.floor(u / 3.2) - 1.6)
        pv = np.abs(v - 3.0 * np.floor(v / 3.0) - 1.7)
        win = _coverage(pu, 0.65, fp) * _coverage(pv, 0.6, fp) * _coverage(1.0 - v, 0.0, fp)
        g *= 1.0 - 0.65 * win
    elif tex == Tex.POST:  # a dark band
        g = g * (1.0 - 0.85 * _coverage(np.abs(v - 0.75), 0.1, fp))
    elif tex == Tex.VEHICLE:  # windows and a bumper line
        dark = np.maximum(
            _coverage(np.abs(v - 1.08), 0.22, fp), _coverage(np.abs(v - 0.35), 0.12, fp) * 0.8
        )
        g = g * (1.0 - 0.6 * dark)
    return np.asarray(np.broadcast_to(g, (rows, TEX_SIZE)))


def _road_tile(
    half_m: float, lanes: int, lane_width_m: float, ground_half_m: float, tpm_v: float
) -> FloatArray:
    """Colour tile of the ground (BGR in [0, 1], ``(rows, 512, 3)``): asphalt with edge lines
    and dashed lane separators within ``±half_m``, grass beyond; columns at
    ``Tex.TEXELS_PER_M[ROAD]``, rows at ``tpm_v`` texels per metre from ``v = −ground_half_m``."""
    base = _base_textures()
    tpm = float(Tex.TEXELS_PER_M[Tex.ROAD])
    rows = math.ceil(2.0 * ground_half_m * tpm_v) + 1
    reps = -(-rows // TEX_SIZE)
    a = np.tile(base["asphalt"], (reps, 1))[:rows]
    grass = np.tile(base["grass"], (reps, 1))[:rows]
    u = (np.arange(TEX_SIZE) / tpm)[None, :]
    v = (-ground_half_m + np.arange(rows) / tpm_v)[:, None]
    fp = 1.0 / tpm
    cover = _coverage(np.abs(np.abs(v) - (half_m - 0.25)), LINE_HALF_WIDTH_M, fp)
    if lanes > 1:
        k = np.clip(np.rint((v + half_m) / lane_width_m), 1, lanes - 1)
        d = np.abs(v + half_m - k * lane_width_m)
        period = DASH_M + GAP_M
        phase = u - period * np.floor(u / period)
        inside = np.minimum(phase, DASH_M - phase)  # > 0 within a dash
        dash = _coverage(-inside, 0.0, fp)
        cover = np.maximum(cover, _coverage(d, LINE_HALF_WIDTH_M, fp) * dash)
    white = MARKING_WHITE / ASPHALT_TINT.mean() * (0.9 + 0.1 * a)
    road = (a + (white - a) * cover)[..., None] * ASPHALT_TINT
    on_road = _coverage(np.abs(v), half_m, fp)[..., None]
    return np.asarray(on_road * road + (1.0 - on_road) * (grass[..., None] * GRASS_TINT))


def _sky_tile() -> FloatArray:
    """Colour tile of the sky (BGR in [0, 1]) over azimuth (columns) and elevation (rows): a
    gradient from the horizon to 25° and clouds."""
    cloud = _base_textures()["cloud"]
    rows = Tex.ROWS[Tex.SKY]
    c = cloud[(np.arange(rows) - 683) % TEX_SIZE]  # row 683 = the horizon = cloud row 0
    el = (Tex.V_MIN_M[Tex.SKY] + np.arange(rows) / Tex.TEXELS_PER_M_V[Tex.SKY])[:, None, None]
    t_el = np.clip(el / 25.0, 0.0, 1.0)
    cover = np.clip((c - 0.45) * 2.5, 0.0, 1.0)[..., None]
    sky = SKY_HORIZON + (SKY_ZENITH - SKY_HORIZON) * t_el
    return np.asarray(sky + (0.97 - sky) * cover)


def _mip_levels(tile: FloatArray) -> list[NDArray[np.uint8]]:
    """The ``MIP_LEVELS`` levels of a tile (grey or BGR in [0, 1], 512 columns): level ``l``
    blurred by ``_level_sigma(l)``, then every ``MIP_DECIMATION[l]``-th row and column; BGR
    uint8 with the
    first column repeated at the end (bilinear sampling wraps)."""
    colour = tile if tile.ndim == 3 else tile[..., None]
    out = []
    for lev in range(MIP_LEVELS):
        s, step = _level_sigma(lev), MIP_DECIMATION[lev]
        chans = [_blur_wrap_x(colour[..., c], s, s)[::step, ::step] for c in range(colour.shape[2])]
        img = np.stack(chans, axis=-1)
        img = np.concatenate([img, img[:, :1]], axis=1)
        if img.shape[2] == 1:
            img = np.repeat(img, 3, axis=2)
        out.append(np.clip(np.rint(img * 255.0), 0, 255).astype(np.uint8))
    return out


def _level_x0() -> NDArray[np.int64]:
    """First column of each level's tile (levels side by side, each with one column more: the
    first repeated)."""
    widths = [TEX_SIZE // d + 1 for d in MIP_DECIMATION]
    return np.concatenate([[0], np.cumsum(widths)[:-1]]).astype(np.int64)


ATLAS_WIDTH = sum(TEX_SIZE // d + 1 for d in MIP_DECIMATION)


U_REBASE_M = 32.0
"""The ground's and walls' texture ``u`` (distance along the road) is taken relative to a
multiple of this near the camera (a multiple of every texture's period, metres), to keep texel
coordinates small."""
ATLAS_MAX_ROWS = 32000
"""``cv2.remap`` reads images of fewer than 32767 rows."""
LEVEL_ROW_STEP = max(MIP_DECIMATION)
"""Textures start at multiples of this many rows of level 0 (whole rows at every level)."""


def _stack(tiles: dict[int, list[NDArray[np.uint8]]]) -> tuple[NDArray[np.uint8], dict[int, int]]:
    """Textures' levels in one image: level ``l`` in the columns from ``_level_x0()[l]``, each
    texture's level-``l`` tile from row ``y0 / 2^l`` (``y0``: its first row at level 0, a
    multiple of ``LEVEL_ROW_STEP``), ``TILE_PAD`` repeated rows above and below at every
    level. Returns the image and ``y0`` of each texture."""
    gap = 2 * TILE_PAD * LEVEL_ROW_STEP
    y0, row = {}, gap // 2
    for t, levels in tiles.items():
        y0[t] = row
        row += -(-levels[0].shape[0] // LEVEL_ROW_STEP) * LEVEL_ROW_STEP + gap
    image = np.zeros((row - gap // 2, ATLAS_WIDTH, 3), np.uint8)
    x0 = _level_x0()
    for t, levels in tiles.items():
        for lev, img in enumerate(levels):
            r = y0[t] // MIP_DECIMATION[lev] - TILE_PAD
            padded = np.pad(img, ((TILE_PAD, TILE_PAD), (0, 0), (0, 0)), mode="edge")
            image[r : r + padded.shape[0], x0[lev] : x0[lev] + img.shape[1]] = padded
    return image, y0


@functools.lru_cache(maxsize=1)
def _shared_levels() -> dict[int, list[NDArray[np.uint8]]]:
    """Mip levels of the wall, box and sky textures."""
    return {
        t: _mip_levels(_sky_tile() if t == Tex.SKY else _grey_tile(t))
        for t in (Tex.FACADE, Tex.FOLIAGE, Tex.OBJECT, Tex.POST, Tex.VEHICLE, Tex.SKY)
    }


@dataclass(frozen=True)
class Atlas:
    """Textures of one road layout in one image.

    Level ``l`` (``s = 1 / MIP_DECIMATION[l]``) of texture ``t`` holds ``(u, v)`` (metres in the
    texture's frame) at column ``x0[l] + s · ((u · TEXELS_PER_M[t]) mod 512)`` and row
    ``s · (y0[t] + (v − v_min[t]) · tpm_v[t])`` (see :func:`atlas_xy`).

    Attributes:
        image: ``(rows, ATLAS_WIDTH, 4)`` uint8 BGRA.
        y0: ``(COUNT,)`` first row of each texture at level 0.
        v_min, tpm_v: ``(COUNT,)`` metres, texels per metre along ``v`` at level 0.
    """

    image: NDArray[np.uint8]
    y0: FloatArray
    v_min: FloatArray
    tpm_v: FloatArray


@functools.lru_cache(maxsize=4)
def texture_atlas(half_m: float, lanes: int, lane_width_m: float, ground_half_m: float) -> Atlas:
    """The atlas of one road layout (the ground spans ``±ground_half_m``)."""
    shared = _shared_levels()
    used = sum(-(-lv[0].shape[0] // LEVEL_ROW_STEP) * LEVEL_ROW_STEP for lv in shared.values())
    budget = ATLAS_MAX_ROWS - used - 4 * TILE_PAD * LEVEL_ROW_STEP * (len(shared) + 1)
    tpm_v = Tex.TEXELS_PER_M_V.copy()
    tpm_v[Tex.ROAD] = min(tpm_v[Tex.ROAD], budget / (2.0 * ground_half_m))
    road = _mip_levels(
        _road_tile(half_m, lanes, lane_width_m, ground_half_m, float(tpm_v[Tex.ROAD]))
    )
    image, first = _stack({Tex.ROAD: road, **shared})
    v_min = Tex.V_MIN_M.copy()
    v_min[Tex.ROAD] = -ground_half_m
    y0 = np.array([first[t] for t in range(Tex.COUNT)], np.float64)
    bgra = cv2.cvtColor(image, cv2.COLOR_BGR2BGRA)
    return Atlas(np.asarray(bgra, dtype=np.uint8), y0, v_min, tpm_v)


LEVEL_X0 = np.zeros(256, np.float32)
"""First column of each mip level (a lookup table indexed by the level as uint8)."""
LEVEL_X0[:MIP_LEVELS], LEVEL_X0[MIP_LEVELS:] = _level_x0(), _level_x0()[-1]
LEVEL_SCALE = np.zeros(256, np.float32)
"""Scale of each mip level's texel coordinates, ``1 / MIP_DECIMATION`` (indexed likewise)."""
LEVEL_SCALE[:MIP_LEVELS] = 1.0 / np.asarray(MIP_DECIMATION)
LEVEL_SCALE[MIP_LEVELS:] = LEVEL_SCALE[MIP_LEVELS - 1]


def atlas_xy(tx: F32, ty: F32, level: NDArray[np.uint8]) -> tuple[F32, F32]:
    """Atlas coordinates of level-0 texel coordinates ``(tx, ty)`` (``ty`` from the atlas's first
    row) at mip level ``level`` (uint8, 2-D). Overwrites ``tx`` and ``ty``."""
    tx *= np.float32(1.0 / TEX_SIZE)
    return _atlas_xy_periods(tx, ty, level)


def _atlas_xy_periods(tu: F32, ty: F32, level: NDArray[np.uint8]) -> tuple[F32, F32]:
    """:func:`atlas_xy` of ``tu = tx / TEX_SIZE`` (``u`` in periods of the tiles). Overwrites
    ``tu`` and ``ty``."""
    tu -= np.floor(tu)  # u wraps round the tiles
    scale = cv2.LUT(level, LEVEL_SCALE)
    cv2.multiply(tu, scale, dst=tu, scale=float(TEX_SIZE))
    tu += cv2.LUT(level, LEVEL_X0)
    ty *= scale
    return tu, ty


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


SUN_DIRECTION = np.array([0.35, -0.45, 0.82]) / np.linalg.norm([0.35, -0.45, 0.82])
"""Unit vector towards the sun, world frame (for face shading)."""
SKY_HORIZON = np.array([0.93, 0.88, 0.84], np.float32)
SKY_ZENITH = np.array([0.80, 0.55, 0.33], np.float32)
HAZE = np.array([0.88, 0.85, 0.82], np.float32)


@functools.lru_cache(maxsize=8)
def _haze_rows(n: int) -> F32:
    """``(n, 4)`` rows of the haze's BGR0 colour × 255."""
    return np.tile(np.float32(255.0) * np.append(HAZE, np.float32(0.0)), (n, 1))


def _haze_row(n: int) -> F32:
    """The haze's BGR0 colour × 255 repeated ``n`` times, ``(n, 4)`` (shared, read only)."""
    size = 1 << max(n - 1, 1).bit_length()  # few sizes cached
    return _haze_rows(max(size, n))[:n]


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


def clip_polygon_rect(
    poly_px: FloatArray, x0: float, y0: float, x1: float, y1: float
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


@dataclass(frozen=True)
class _Tables:
    """Per-label tables of one frame (label 0 = sky).

    Attributes:
        per_label: ``(11, n + 1)`` float32, one row per quantity (gathered together): rows 0–8
            the pixel functionals ``(h_x, h_y, h_w)``: ``1/z = h_w·p``, texel coordinates
            ``t_x = TEX_SIZE (h_x·p)/(h_w·p)`` (``h_x`` in periods of the tiles),
            ``t_y = (h_y·p)/(h_w·p)`` (level 0, ``t_y`` from the atlas's first row); row 9
            ``log2`` of the texture's texels per metre along ``v`` minus ``MIP_BIAS``; row 10
            ``log2`` of the plane's distance from the camera centre (m) times the
            foreshortening that does not raise the mip level (see ``_level``).
        tint: ``(n + 1, 4)`` float32, the BGR colour × sun shading in [0, 1] and a 0.
        tex: ``(n + 1,)`` texture.
        surface: ``(n + 1,)`` surface of each label (equal for pieces of one surface).
        turn: ``(n + 1,)`` angle the surface's normal has turned through from its first label's
            piece to each label's (radians, summed piece to piece): between labels ``a < b`` of
            one surface every piece's normal is within ``turn[b] − turn[a]`` of the others'.
    """

    per_label: NDArray[np.float32]
    tint: NDArray[np.float32]
    tex: NDArray[np.intp]
    surface: NDArray[np.int64]
    turn: FloatArray


class Renderer:
    """Renders frames of one world (static polygons) seen by one camera.

    Args:
        static: the world's polygons in painter order (:func:`~slopedist.datasets.synthetic.
            world.static_world`).
        K: 3×3 intrinsics; width, height: image size in pixels.
        carriageway_half_m: half-width of the asphalt; lanes, lane_width_m: lane layout
            (for the markings).
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
        carriageway_half_m: float,
        lanes: int,
        lane_width_m: float,
        seed: int = 0,
        interpolate: bool = True,
    ) -> None:
        self.interpolate = interpolate
        self.static = static
        self.K = np.asarray(K, dtype=float)
        self.K_inv = np.linalg.inv(self.K)
        self.width, self.height = int(width), int(height)
        self.half = float(carriageway_half_m)
        self.lanes = int(lanes)
        self.lane_width = float(lane_width_m)
        ground = static.material == int(Material.GROUND)
        if ground.any():
            g = static.select(np.flatnonzero(ground))
            v = np.einsum("pkj,pj->pk", g.verts - g.origin[:, None], g.axis_v)
            ground_half = float(np.abs(v).max()) + 1.0
        else:
            ground_half = self.half + 1.0
        self._combined: Polygons | None = None
        self._atlas = texture_atlas(self.half, self.lanes, self.lane_width, round(ground_half, 3))
        self._mat_tex = np.zeros(len(Material), np.intp)
        for m, t in MATERIAL_TEXTURE.items():
            self._mat_tex[int(m)] = t
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

    def _visible_polygons(
        self, polys: Polygons, painter: NDArray[np.intp], R_wc: FloatArray, C_w: FloatArray
    ) -> tuple[NDArray[np.intp], list[NDArray[np.int32]]]:
        """Cull, clip and project the polygons ``polys[painter]`` (painter order); returns the
        indices (into ``painter``) of the kept ones and their integer pixel outlines
        (``cv2.fillConvexPoly`` coordinates, 4 fractional bits)."""
        verts = polys.verts[painter]
        facing = polys.two_sided[painter] | (
            np.einsum("pi,pi->p", C_w - verts[:, 0], polys.normal[painter]) > 1e-9
        )
        idx = np.flatnonzero(facing)
        vc = (verts[idx] - C_w) @ R_wc  # (p, k, 3): camera frame
        x, y, z = np.ascontiguousarray(vc.transpose(2, 1, 0))  # (k, p) each
        all_in = np.logical_and.reduce(z >= NEAR_CLIP_M, axis=0)
        any_in = np.logical_or.reduce(z >= NEAR_CLIP_M, axis=0)
        K = self.K
        zz = np.where(all_in, z, 1.0)
        px_x = K[0, 0] * x / zz + K[0, 2]
        px_y = K[1, 1] * y / zz + K[1, 2]
        w, h = self.width, self.height
        lo_x, hi_x = px_x.min(axis=0), px_x.max(axis=0)
        lo_y, hi_y = px_y.min(axis=0), px_y.max(axis=0)
        onscreen = (hi_x >= -1) & (lo_x <= w) & (hi_y >= -1) & (lo_y <= h)
        lim = FILL_LIMIT_PX
        huge = (lo_x < -lim) | (lo_y < -lim) | (hi_x > w + lim) | (hi_y > h + lim)
        direct = np.flatnonzero(all_in & onscreen & ~huge)
        px = np.stack([px_x, px_y], axis=-1).transpose(1, 0, 2)  # (p, k, 2)
        outlines: dict[int, NDArray[np.int32]] = dict(
            zip(direct.tolist(), np.round(px[direct] * 16.0).astype(np.int32), strict=True)
        )
        # crossing the near plane, or reaching beyond fillConvexPoly's range: clipped
        for p in np.flatnonzero((any_in & ~all_in) | (all_in & onscreen & huge)).tolist():
            if all_in[p]:
                q = px[p]
            else:
                poly = clip_polygon_near(vc[p])
                if poly.shape[0] < 3:
                    continue
                q = np.stack(
                    [
                        K[0, 0] * poly[:, 0] / poly[:, 2] + K[0, 2],
                        K[1, 1] * poly[:, 1] / poly[:, 2] + K[1, 2],
                    ],
                    axis=-1,
                )
            if np.any(q < -lim) or np.any(q > (w + lim, h + lim)):
                q = clip_polygon_rect(q, -4.0, -4.0, w + 4.0, h + 4.0)
                if q.shape[0] < 3:
                    continue
            outlines[p] = np.round(q * 16.0).astype(np.int32)
        keep = sorted(outlines)  # painter order is index order
        return idx[np.asarray(keep, dtype=np.intp)], [outlines[p] for p in keep]

    def _tables(
        self,
        polys: Polygons,
        surface: NDArray[np.int64],
        R_wc: FloatArray,
        C_w: FloatArray,
        u_base: float,
    ) -> _Tables:
        """The per-label tables of ``polys`` (in label order, label = index + 1)."""
        n = len(polys)
        n_c = polys.normal @ R_wc  # rows: (R_wcᵀ n)ᵀ, the normals in the camera frame
        x0_c = (polys.verts[:, 0] - C_w) @ R_wc
        o_c = (polys.origin - C_w) @ R_wc
        c = np.einsum("pi,pi->p", n_c, x0_c)  # plane: n_c · X = c
        c = np.where(np.abs(c) < 1e-9, 1e-9, c)
        K_inv = self.K_inv
        h_w = (n_c @ K_inv) / c[:, None]  # 1/z = h_w · p
        tex = self._mat_tex[polys.material]
        tpm_u = Tex.TEXELS_PER_M[tex]
        tpm_v = self._atlas.tpm_v[tex]
        a_u, a_v = polys.axis_u @ R_wc, polys.axis_v @ R_wc
        along_road = polys.surface >= 0  # u = distance along the road: rebased
        k_u = polys.u0 - np.where(along_road, u_base, 0.0) - np.einsum("pi,pi->p", a_u, o_c)
        k_v = -np.einsum("pi,pi->p", a_v, o_c) - self._atlas.v_min[tex]
        k_v += self._atlas.y0[tex] / tpm_v  # rows from the atlas's first
        h_x = (tpm_u / TEX_SIZE)[:, None] * (a_u @ K_inv + k_u[:, None] * h_w)
        h_y = tpm_v[:, None] * (a_v @ K_inv + k_v[:, None] * h_w)
        fn = np.zeros((n + 1, 9), np.float32)
        fn[1:] = np.concatenate([h_x, h_y, h_w], axis=1)
        plane_c = np.ones(n + 1, np.float32)
        plane_c[1:] = np.abs(c)
        shade = 0.62 + 0.38 * np.clip(polys.normal @ SUN_DIRECTION, 0.0, 1.0)
        tint = np.zeros((n + 1, 4), np.float32)
        tint[1:, :3] = polys.colour * shade[:, None]
        tint[1:, :3][tex == Tex.ROAD] = 1.0  # the road's colours are in its texture
        tex_l = np.full(n + 1, Tex.SKY, np.intp)
        tex_l[1:] = tex
        tpm = np.ones(n + 1, np.float32)
        tpm[1:] = tpm_v
        surf = np.full(n + 1, -1, np.int64)
        surf[1:] = surface
        cos = np.einsum("pi,pi->p", polys.normal[1:], polys.normal[:-1])
        step = np.where(surface[1:] == surface[:-1], np.arccos(np.clip(cos, -1.0, 1.0)), 0.0)
        turn = np.zeros(n + 1)
        turn[2:] = np.cumsum(step)
        free = np.where(tex_l == Tex.ROAD, ROAD_FORESHORTENING_FREE, 1.0).astype(np.float32)
        log_tpm = np.log2(tpm) - np.float32(MIP_BIAS)
        log_c = np.log2(np.maximum(plane_c * free, np.float32(1e-3)))
        per_label = np.concatenate([fn.T, log_tpm[None], log_c[None]])
        return _Tables(np.ascontiguousarray(per_label, dtype=np.float32), tint, tex_l, surf, turn)

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
        visible, outlines = self._visible_polygons(polys, painter, R, C)
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
        tab = self._tables(ordered, key[order], R, C, u_base)
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
        + log2(tpm) − MIP_BIAS + max(log2 z − log2(|c|·free), 0)`` (``_Tables.per_label``)."""
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
        self, labels: NDArray[np.uint16], tab: _Tables, R: FloatArray, frame: int
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
            mapx, mapy = _atlas_xy_periods(mapx, mapy, level)
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
        tab: _Tables,
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
        tab: _Tables,
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


def vehicle_polygons(
    corners_world: FloatArray,
    colours_bgr: FloatArray,
    s_rear: FloatArray,
    s_front: FloatArray,
    owners: NDArray[np.int64],
) -> Polygons:
    """Faces of target boxes from their 8 corners ``(M, 8, 3)`` (order of
    :data:`~slopedist.datasets.synthetic.vehicles.BOX_CORNERS_UNIT`); colours BGR in [0, 1]."""
    c = corners_world
    fwd = c[:, 2] - c[:, 0]
    lft = c[:, 1] - c[:, 0]
    up = c[:, 4] - c[:, 0]
    fwd, lft, up = (a / np.linalg.norm(a, axis=1, keepdims=True) for a in (fwd, lft, up))
    faces = [
        ((0, 1, 5, 4), -fwd, lft),
        ((3, 2, 6, 7), fwd, -lft),
        ((2, 0, 4, 6), -lft, -fwd),
        ((1, 3, 7, 5), lft, fwd),
        ((4, 5, 7, 6), up, lft),
    ]
    m = c.shape[0]
    parts = []
    for idx, normal, axis_u in faces:
        v = c[:, list(idx)]
        parts.append(
            Polygons(
                verts=v,
                normal=normal,
                origin=v[:, 0],
                axis_u=axis_u,
                axis_v=up,
                u0=np.zeros(m),
                key=s_rear.copy(),
                layer=np.full(m, int(Layer.VEHICLE)),
                s_lo=s_rear.copy(),
                s_hi=s_front.copy(),
                material=np.full(m, int(Material.VEHICLE)),
                colour=colours_bgr.copy(),
                owner=owners.astype(np.int64),
                two_sided=np.zeros(m, bool),
                lod=np.full(m, -1, np.int8),
                lod_key=np.zeros(m),
                surface=np.full(m, -1, np.int64),
            )
        )
    return Polygons.concat(parts)
