"""Evaluation: metrics, the KITTI protocol, accuracy tables, plots and the comparison report.

Internal: the names a user needs are those of :mod:`slopedist` itself (docs/python.md).
"""
