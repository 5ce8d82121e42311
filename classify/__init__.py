"""classify: recognize objects from tactile imprints.

The five classifiers of the paper (``NAMES``, ``make``) and the experiment
behind its Tables 1 and 2 (``run_experiment``, ``run_real``): interest
points -> imprints -> recognition under two protocols.  Public names are
loaded on first use, so that the ``visuotactile`` command (``classify.cli``)
starts without importing scikit-learn.
"""

from meshsal.lazy import attach

NAMES = ("knn", "naive_bayes", "decision_tree", "evolutionary_svm", "deep")

_EXPORTS = {
    "make": "classifiers",
    "as_matrix": "classifiers",
    "KNN": "classifiers",
    "NaiveBayes": "classifiers",
    "DecisionTree": "classifiers",
    "EvolutionarySVM": "classifiers",
    "DeepNet": "classifiers",
    "METHODS": "experiment",
    "PROTOCOLS": "experiment",
    "Cell": "experiment",
    "ConfusionMatrix": "experiment",
    "ExperimentResult": "experiment",
    "run_experiment": "experiment",
    "run_real": "experiment",
    "format_tables": "experiment",
    "write_outputs": "experiment",
}
_SUBMODULES = {"classifiers", "evolutionary_svm", "experiment", "report", "cache", "cli"}

__getattr__, __dir__, __all__ = attach(__name__, _EXPORTS, _SUBMODULES, eager=("NAMES",))
