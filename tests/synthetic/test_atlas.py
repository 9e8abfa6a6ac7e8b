"""The texture atlas: every level of every texture where :func:`atlas_xy` says it is."""

from __future__ import annotations

import cv2
import numpy as np

from slopedist.synthetic import atlas as at
from slopedist.synthetic.textures import TEX_SIZE, LaneLayout, Tex


def test_atlas_levels_hold_the_texture_where_atlas_xy_points() -> None:
    atlas = at.texture_atlas(LaneLayout(3.5, 2, 3.5), 10.5)
    tiles = at.shared_levels()[Tex.FACADE]
    rng = np.random.default_rng(1)
    for level in range(at.MIP_LEVELS):
        step = at.MIP_DECIMATION[level]
        rows, cols = tiles[level].shape[:2]
        i = rng.integers(0, rows, 50)
        j = rng.integers(0, cols - 1, 50)
        # level-0 texel coordinates of those texels, u shifted by whole periods (wraps)
        tx = (j * step + TEX_SIZE * rng.integers(-40, 40, 50)).astype(np.float32)
        ty = (i * step + atlas.y0[Tex.FACADE]).astype(np.float32)
        x, y = at.atlas_xy(tx[None], ty[None], np.full((1, 50), level, np.uint8))
        got = cv2.remap(atlas.image, x, y, cv2.INTER_LINEAR)[0, :, :3]
        np.testing.assert_array_equal(got, tiles[level][i, j])
