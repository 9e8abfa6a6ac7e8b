"""The streaming application: the per-frame step, the run loop over frames and its sinks
(records, overlay, MCAP, TUM poses), and the mount calibration from a drive."""
