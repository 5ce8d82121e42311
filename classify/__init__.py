"""classify: recognize objects from tactile imprints.

The sub-packages: ``recognizers`` (the five classifiers of the paper and
touch fusion), ``experiment`` (the recognition experiment behind the
paper's Tables 1 and 2 as typed stages: objects -> instance samples ->
protocols -> cells), ``reporting`` (statistics, tables, files), ``runtime``
(where work runs, the cache) and ``batch`` (points and imprints for a folder
of meshes on a cluster).  Public names are loaded on first use, so that the ``visuotactile`` command (``classify.cli``)
starts without importing scikit-learn; modules of the flat layout before 0.2
(``classify.dataset``, ``classify.stats``...) still import, as the modules
that replaced them.
"""

from meshsal.util.lazy import attach

_EXPORTS = {
    "NAMES": "recognizers.classifiers",
    "PAPER_NAMES": "recognizers.classifiers",
    "PlaceAware": "recognizers.place",
    "CLASSIFIERS": "recognizers.classifiers",
    "make": "recognizers.classifiers",
    "as_matrix": "recognizers.classifiers",
    "KNN": "recognizers.classifiers",
    "NaiveBayes": "recognizers.classifiers",
    "DecisionTree": "recognizers.classifiers",
    "EvolutionarySVM": "recognizers.classifiers",
    "DeepNet": "recognizers.classifiers",
    "METHODS": "experiment",
    "run_batch": "batch",
    "load_store": "batch",
    "PROTOCOLS": "experiment.protocols",
    "Settings": "experiment",
    "TouchEnv": "experiment.env",
    "Cell": "reporting.results",
    "Comparison": "reporting.results",
    "ConfusionMatrix": "reporting.results",
    "ExperimentResult": "reporting.results",
    "run_experiment": "experiment",
    "run_real": "experiment",
    "format_tables": "reporting.results",
    "write_outputs": "reporting.results",
}
_SUBMODULES = {"recognizers", "experiment", "reporting", "runtime", "batch", "cli"}
#: Where each module of the flat layout went.
_MOVED = {
    "classifiers": "recognizers.classifiers",
    "evolutionary_svm": "recognizers.evolutionary_svm",
    "fusion": "recognizers.fusion",
    "dataset": "experiment.samples",
    "learned": "experiment.survey",
    "protocols": "experiment.protocols",
    "results": "reporting.results",
    "report": "reporting.report",
    "stats": "reporting.stats",
    "cluster": "runtime.cluster",
    "cache": "runtime.cache",
}

__getattr__, __dir__, __all__ = attach(__name__, _EXPORTS, _SUBMODULES, _MOVED)
