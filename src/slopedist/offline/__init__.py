"""Offline tools: run once on labelled data to produce the shipped defaults, never at run time.

:mod:`.ours_fitting` fits the heading prior and the box-edge noise of ``ours`` to KITTI labels
(used by ``benchmarks/ours_kitti.py``).
"""
