"""The foundations every layer uses: the paper's equations as pure functions (``geometry``), the
camera and its calibration (``camera``), the exception hierarchy (``errors``), the bounds on input
(``limits``) and strict text reading (``textfiles``)."""
