"""Small experiments for the tests: a quick :class:`ExperimentConfig` to ``.replace`` and a run without cache or bars."""

from classify.experiment import run_experiment
from classify.experiment.config import ExperimentConfig, Settings
from tactile import Sensor

#: Six points an instance, two training instances of one acquisition session each; views of 48 pixels and
#: imprints of 2 x 2 rays a taxel (the channels' and the imprints' own tests take full-size ones: here they
#: only choose, describe and tell apart places).
SMALL = Settings(n_points=6, train_instances=2, train_sessions=1, view_size=48, sensor=Sensor(supersample=2))
#: k-NN on ``SMALL``: two replicates, and two repeats of three folds in the paper protocol.
QUICK = ExperimentConfig(classifiers=("knn",), settings=SMALL, replicates=2, repeats=2, folds=3)


def run(objects, config=QUICK, cache_dir=None, **options):
    """:func:`classify.experiment.run_experiment` with no progress bars, and no cache unless given one.

    ``options`` are its other keywords (``n_jobs``, ``executor``, ``out_dir``).
    """
    return run_experiment(objects, config, cache_dir=cache_dir, quiet=True, **options)
