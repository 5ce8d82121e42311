"""The recognition experiment as typed stages: objects -> instance samples -> protocols -> measurements.

``config`` (what to measure: :class:`ExperimentConfig`, :class:`Settings`),
``streams`` (the named random streams every draw comes from), ``samples``
(one object's instances, points and imprints), ``survey`` (touch surveys and
the learned touch model), ``protocols`` (the paper's and the instance
protocol's jobs), ``stages`` (the stages that run them on a pool) and
``run`` (:func:`run_experiment`, :func:`run_real`).  Public names of
:mod:`classify.experiment.run` are re-exported here.
"""

from classify.experiment.run import *  # noqa: F401,F403
from classify.experiment.run import __all__  # noqa: F401
