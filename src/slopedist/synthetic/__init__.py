"""Synthetic hills and the demo: a road model, vehicles, exact ground truth, a renderer, detector
noise, and ``slopedist demo`` (:mod:`~slopedist.synthetic.demo`) that runs every method on them.

``load_scenario(name_or_path)`` reads a built-in scenario or a TOML file
(:mod:`~slopedist.synthetic.scenarios`); ``simulate_truth`` drives it
(:mod:`~slopedist.synthetic.scene`); :class:`~slopedist.synthetic.sequence.
SyntheticSequence` renders its frames with boxes and depth maps.
:func:`~slopedist.synthetic.traffic.simulate_traffic` is the light-weight counterpart
for ``ours``: exactly projected 3D boxes on a flat road, no images.

Internal: the names a user needs are those of :mod:`slopedist` itself (docs/python.md).
"""
