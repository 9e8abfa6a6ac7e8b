"""Readers of the KITTI datasets (tracking, raw, odometry)."""
