"""The foundations every layer uses: the paper's equations as pure functions (``geometry``), the
camera and its calibration (``camera``), the exception hierarchy (``errors``), the bounds on input
(``limits``), strict text reading (``textfiles``), which of many rectangles hold a point
(``rectangles``) and the "did you mean" of a mistyped name (``suggest``).

Internal: the names a user needs are those of :mod:`slopedist` itself (docs/python.md).
"""
