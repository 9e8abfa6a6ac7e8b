"""Dataset readers (KITTI tracking, raw, odometry) and synthetic scenes."""
