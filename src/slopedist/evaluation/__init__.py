"""Evaluation: metrics, the KITTI protocol, accuracy tables, plots and the comparison report."""
