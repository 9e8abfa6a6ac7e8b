"""The streaming application: :class:`~slopedist.streaming.pipeline.Pipeline` (calibration,
method and odometry in; per frame, image and boxes in, per-target results out) over the
per-frame step (:mod:`~slopedist.streaming.step`), the run into a folder
(:mod:`~slopedist.streaming.setup`, :mod:`~slopedist.streaming.loop`) and its sinks (records,
overlay, MCAP, TUM poses), and the mount calibration from a drive.

Internal: the names a user needs are those of :mod:`slopedist` itself (docs/python.md).
"""
