"""slopedist: monocular inter-vehicle distance estimation with ego and target road gradients.

Implements Back et al., "Improved and efficient inter-vehicle distance estimation using road
gradients of both ego and target vehicles", its baselines, and improvements on top of it.
"""

__version__ = "0.2.0"
