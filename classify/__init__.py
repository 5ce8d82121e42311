"""classify: recognize objects from tactile imprints.

The five classifiers of the paper (``NAMES``, ``make``) and the experiment
behind its Tables 1 and 2 (``run_experiment``, ``run_real``): interest
points -> imprints -> recognition under the paper's protocol and on fresh
object instances, with bootstrap intervals and paired comparisons.  Public names are
loaded on first use, so that the ``visuotactile`` command (``classify.cli``)
starts without importing scikit-learn.
"""

from meshsal.lazy import attach

_EXPORTS = {
    "NAMES": "classifiers",
    "CLASSIFIERS": "classifiers",
    "make": "classifiers",
    "as_matrix": "classifiers",
    "KNN": "classifiers",
    "NaiveBayes": "classifiers",
    "DecisionTree": "classifiers",
    "EvolutionarySVM": "classifiers",
    "DeepNet": "classifiers",
    "METHODS": "experiment",
    "run_batch": "batch",
    "load_store": "batch",
    "PROTOCOLS": "protocols",
    "Settings": "dataset",
    "Cell": "results",
    "Comparison": "results",
    "ConfusionMatrix": "results",
    "ExperimentResult": "results",
    "run_experiment": "experiment",
    "run_real": "experiment",
    "format_tables": "results",
    "write_outputs": "results",
}
_SUBMODULES = {"classifiers", "evolutionary_svm", "experiment", "protocols", "dataset", "fusion", "stats", "results",
               "report", "cache", "cli", "batch", "cluster"}

__getattr__, __dir__, __all__ = attach(__name__, _EXPORTS, _SUBMODULES)
