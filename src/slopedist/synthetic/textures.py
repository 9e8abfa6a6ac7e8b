"""Procedural textures of the synthetic hills: the tiles the renderer's atlas is made of.

Every texture is a periodic grey 1/f-noise tile (fixed seed) with its details baked in: lane
markings, verge and grass on the road's tile, windows on the façades, bands on the posts,
windows and bumper line on the vehicles, the sky's gradient and clouds. Tiles are world-anchored:
a texture's ``u`` runs along the surface (``TEXELS_PER_M`` texels per metre, period
``TEX_SIZE`` texels), its ``v`` across it (see :mod:`~slopedist.synthetic.polygons`).
Colours are BGR in [0, 1]; :mod:`~slopedist.synthetic.atlas` turns the tiles into mip
levels in one image.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from slopedist.synthetic.polygons import Material

FloatArray = NDArray[np.float64]

TEX_SIZE = 512
"""Period of every texture along its ``u`` axis (the atlas's width), texels."""

U_REBASE_M = 32.0
"""The ground's and walls' texture ``u`` (distance along the road) is taken relative to a
multiple of this near the camera (a multiple of every texture's period, metres), to keep texel
coordinates small."""


class LaneLayout(NamedTuple):
    """What the road's tile draws: the asphalt's half-width (metres), the number of lanes and
    their width (metres); the edge lines and dashed separators follow from them."""

    carriageway_half_m: float
    lanes: int
    lane_width_m: float


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


DASH_M, GAP_M = 3.0, 5.0
"""Lane separators: 3 m dashes with 5 m gaps (one period per road tile)."""
LINE_HALF_WIDTH_M = 0.075
MARKING_WHITE = 0.93
ASPHALT_TINT = np.array([0.62, 0.62, 0.64])
GRASS_TINT = np.array([0.30, 0.55, 0.45])


def grey_tile(tex: int) -> FloatArray:
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


def road_tile(
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


def sky_tile() -> FloatArray:
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


SKY_HORIZON = np.array([0.93, 0.88, 0.84], np.float32)
SKY_ZENITH = np.array([0.80, 0.55, 0.33], np.float32)
