"""Shared fixtures: the real KITTI data in ../shared/data (skipped when absent)."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO_ROOT.parent / "shared" / "data"


KITTI_FIXTURES = frozenset(
    {"kitti_tracking_dir", "kitti_odometry_dir", "kitti_raw_lead_dir", "kitti_report"}
)
"""Fixtures that hand out real KITTI data; a test using one is marked ``kitti``."""


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Mark each test that uses the real data ``kitti`` (``pytest -m "not kitti"`` skips them)."""
    for item in items:
        if KITTI_FIXTURES.intersection(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.kitti)


def shared_data_path(*parts: str) -> Path:
    """Path under ../shared/data, or skip the test with a message when it is absent."""
    path = SHARED_DATA.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"real KITTI data not found at {path} (a fresh clone has no ../shared)")
    return path


@pytest.fixture
def kitti_tracking_dir() -> Path:
    """../shared/data/kitti_tracking, or skip."""
    return shared_data_path("kitti_tracking")


@pytest.fixture
def kitti_odometry_dir() -> Path:
    """../shared/data/kitti_odometry, or skip."""
    return shared_data_path("kitti_odometry")


@pytest.fixture
def kitti_raw_lead_dir() -> Path:
    """../shared/data/kitti_raw_lead, or skip."""
    return shared_data_path("kitti_raw_lead")
