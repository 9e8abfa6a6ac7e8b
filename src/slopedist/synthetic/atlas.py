"""The texture atlas: every texture's mip levels in one image, and where a texel lies in it.

Level ``l`` of a tile is the tile blurred by ``0.6 · 2^(l−1)`` texels (periodic along ``u``) and
decimated by ``MIP_DECIMATION[l]``; levels sit side by side (columns), textures one above the
other (rows), so one ``cv2.remap`` shades a whole frame (see
:mod:`~slopedist.synthetic.render`). Images are BGR(A) uint8.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from slopedist.synthetic.textures import (
    TEX_SIZE,
    LaneLayout,
    Tex,
    grey_tile,
    road_tile,
    sky_tile,
)

FloatArray = NDArray[np.float64]
F32 = NDArray[np.float32]

MIP_LEVELS = 6
MIP_BIAS = 0.5
"""Levels are chosen this much sharper than the footprint says."""
MIP_DECIMATION = (1, 2, 4, 8, 16, 32)
"""Level ``l`` keeps every ``MIP_DECIMATION[l]``-th texel of its blurred tile (neighbouring
pixels stay near in memory)."""
TILE_PAD = 2
"""Rows repeated above and below every tile of the atlas (bilinear sampling at its edges)."""


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


def _mip_levels(tile: FloatArray) -> list[NDArray[np.uint8]]:
    """The ``MIP_LEVELS`` levels of a tile (grey or BGR in [0, 1], 512 columns): level ``l``
    blurred by ``_level_sigma(l)``, then every ``MIP_DECIMATION[l]``-th row and column; BGR
    uint8 with the first column repeated at the end (bilinear sampling wraps)."""
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
def shared_levels() -> dict[int, list[NDArray[np.uint8]]]:
    """Mip levels of the wall, box and sky textures."""
    return {
        t: _mip_levels(sky_tile() if t == Tex.SKY else grey_tile(t))
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
def texture_atlas(layout: LaneLayout, ground_half_m: float) -> Atlas:
    """The atlas of one road layout (the ground spans ``±ground_half_m``)."""
    shared = shared_levels()
    used = sum(-(-lv[0].shape[0] // LEVEL_ROW_STEP) * LEVEL_ROW_STEP for lv in shared.values())
    budget = ATLAS_MAX_ROWS - used - 4 * TILE_PAD * LEVEL_ROW_STEP * (len(shared) + 1)
    tpm_v = Tex.TEXELS_PER_M_V.copy()
    tpm_v[Tex.ROAD] = min(tpm_v[Tex.ROAD], budget / (2.0 * ground_half_m))
    road = _mip_levels(road_tile(*layout, ground_half_m, float(tpm_v[Tex.ROAD])))
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
    return atlas_xy_periods(tx, ty, level)


def atlas_xy_periods(tu: F32, ty: F32, level: NDArray[np.uint8]) -> tuple[F32, F32]:
    """:func:`atlas_xy` of ``tu = tx / TEX_SIZE`` (``u`` in periods of the tiles). Overwrites
    ``tu`` and ``ty``."""
    tu -= np.floor(tu)  # u wraps round the tiles
    scale = cv2.LUT(level, LEVEL_SCALE)
    cv2.multiply(tu, scale, dst=tu, scale=float(TEX_SIZE))
    tu += cv2.LUT(level, LEVEL_X0)
    ty *= scale
    return tu, ty
