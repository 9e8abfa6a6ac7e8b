"""Synthetic hills: a road model, vehicles, exact ground truth, a renderer and detector noise.

``load_scenario(name_or_path)`` reads a built-in scenario or a TOML file
(:mod:`~slopedist.datasets.synthetic.scenarios`); ``simulate_truth`` drives it
(:mod:`~slopedist.datasets.synthetic.scene`); :class:`~slopedist.datasets.synthetic.sequence.
SyntheticSequence` renders its frames with boxes and depth maps.
:func:`~slopedist.datasets.synthetic.traffic.simulate_traffic` is the light-weight counterpart
for ``ours``: exactly projected 3D boxes on a flat road, no images.
"""
