"""Bounds on user input shared by several readers: beyond them a value is a corrupt or hostile
file, not data, and the reader stops with a clear error instead of looping or allocating.

(Ranges that belong to one thing live with it, e.g. the camera's in :mod:`slopedist.core.camera`.)
"""

from __future__ import annotations

MAX_INDEX = 1_000_000_000
"""Largest frame index or track id accepted in any file or file name (a day of 30 fps video is
2.6 million frames)."""

MAX_FRAME_GAP = 1_000
"""Most consecutive frame numbers an image folder may lack between two of its files (100 s at
10 Hz); a larger gap is a stray file, e.g. ``9999999999.png`` among ``0..100``."""

MAX_FRAME_INTERVAL_S = 10.0
"""Largest median time between consecutive frames (a timestamps file) or poses (a pose file),
seconds: a car moves 100+ m in it, so frames that far apart share no view and give no look-back
of a second; timestamps in milli-, micro- or nanoseconds read as seconds do (33 s at 30 Hz)."""

MAX_ABS_POSITION_M = 1e8
"""Largest magnitude of a position in a pose file, metres (twice Earth's circumference; map
coordinates such as UTM stay below 1e7 m)."""

MAX_ABS_PIXEL = 1e6
"""Largest magnitude of a box coordinate, pixels; beyond it a value is not a pixel of any
camera image."""

MAX_RECORD_MAGNITUDE = 1e12
"""Largest magnitude of a number in a run's CSVs (metres, degrees, seconds since the epoch,
milliseconds); beyond it, or infinite, a value is corrupt and would break the figures."""

DEFAULT_MAX_PIXELS = 50_000_000
"""Largest image decoded by default, pixels (50 Mpx: above every dashcam and KITTI frame)."""
