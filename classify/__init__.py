"""classify: recognize objects from tactile imprints.

The five classifiers of the paper (``NAMES``, ``make``) and the experiment
behind its Tables 1 and 2 (``run_experiment``, ``run_real``): interest
points -> imprints -> recognition under two protocols.  Public names are
loaded on first use, so that the ``visuotactile`` command (``classify.cli``)
starts without importing scikit-learn.
"""

import importlib

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

__all__ = ["NAMES"] + sorted(_EXPORTS) + sorted(_SUBMODULES)


def __getattr__(name):
    if name in _EXPORTS:
        value = getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
        globals()[name] = value
        return value
    if name in _SUBMODULES:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return __all__
