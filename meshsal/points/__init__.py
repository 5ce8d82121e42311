"""Where to touch: interest points by visual attention, the baselines and the learned method.

Public names of :mod:`meshsal.points.pipeline` are re-exported here.
"""

from meshsal.points.pipeline import *  # noqa: F401,F403
from meshsal.points.pipeline import __all__  # noqa: F401
