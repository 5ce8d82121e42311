"""classify: recognize objects from tactile imprints.

The sub-packages: ``recognizers`` (the five classifiers of the paper, the
place-aware recognizer and touch fusion), ``policies`` (touch by touch),
``experiment`` (the recognition experiment behind the paper's Tables 1 and 2
as typed stages: objects -> instance samples -> protocols -> cells),
``reporting`` (statistics, tables, files), ``runtime`` (where work runs, the
cache) and ``batch`` (points and imprints for a folder of meshes on a
cluster).  Public names are loaded on first use (``lazy_loader``), so that
the ``visuotactile`` command (``classify.cli``) starts without importing
scikit-learn.  Modules moved in 0.2 are listed in ``CHANGELOG.md``.
"""

import lazy_loader

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
    "ConfusionMatrix": "reporting.confusion",
    "ExperimentResult": "reporting.results",
    "run_experiment": "experiment",
    "run_real": "experiment",
    "format_tables": "reporting.results",
    "write_outputs": "reporting.results",
}
_SUBMODULES = {"recognizers", "experiment", "reporting", "runtime", "batch", "cli"}

__getattr__, __dir__, __all__ = lazy_loader.attach(
    __name__, _SUBMODULES, {m: [n for n, where in _EXPORTS.items() if where == m] for m in set(_EXPORTS.values())}
)
