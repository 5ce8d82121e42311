"""The recognition experiment: objects -> instance samples -> protocols -> rate cells.

Public names of :mod:`classify.experiment.run` are re-exported here.
"""

from classify.experiment.run import *  # noqa: F401,F403
from classify.experiment.run import __all__  # noqa: F401
from classify.experiment.samples import Settings  # noqa: F401
