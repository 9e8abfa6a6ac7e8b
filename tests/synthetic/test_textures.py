"""Procedural tiles: the road's markings and verge where the lane layout puts them."""

from __future__ import annotations

from slopedist.synthetic.textures import (
    DASH_M,
    TEX_SIZE,
    LaneLayout,
    Tex,
    grey_tile,
    road_tile,
)

TPM_V = 16.0  # rows per metre across the road
GROUND_HALF_M = 10.5


def _row(v_m: float) -> int:
    return round((v_m + GROUND_HALF_M) * TPM_V)


def _col(u_m: float) -> int:
    return round(u_m * Tex.TEXELS_PER_M[Tex.ROAD]) % TEX_SIZE


def test_road_tile_draws_dashes_edge_lines_and_grass() -> None:
    layout = LaneLayout(3.5, 2, 3.5)
    tile = road_tile(*layout, GROUND_HALF_M, TPM_V)
    assert tile.shape == (round(2 * GROUND_HALF_M * TPM_V) + 1, TEX_SIZE, 3)
    grey = tile.mean(axis=2)
    lane = grey[_row(1.75), :].mean()  # middle of the left lane, all along
    dash = grey[_row(0.0), _col(0.5 * DASH_M) - 8 : _col(0.5 * DASH_M) + 8].mean()
    gap = grey[_row(0.0), _col(DASH_M + 2.0) - 8 : _col(DASH_M + 2.0) + 8].mean()
    edge = grey[_row(3.25), :].mean()  # the edge line, 0.25 m inside the asphalt's edge
    assert dash > lane + 0.2 and edge > lane + 0.2
    assert abs(gap - lane) < 0.1
    verge = tile[_row(6.0), :].mean(axis=0)  # BGR: grass is green
    asphalt = tile[_row(1.75), :].mean(axis=0)
    assert verge[1] > verge[0] + 0.05 and abs(asphalt[1] - asphalt[0]) < 0.05


def test_grey_tiles_are_periodic_textures_in_range() -> None:
    for tex in (Tex.FACADE, Tex.FOLIAGE, Tex.OBJECT, Tex.POST, Tex.VEHICLE):
        tile = grey_tile(tex)
        assert tile.shape == (Tex.ROWS[tex], TEX_SIZE)
        assert tile.min() >= 0.0 and tile.max() <= 1.0 and tile.std() > 0.02
