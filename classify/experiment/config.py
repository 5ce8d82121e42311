"""What an experiment runs with: the per-object :class:`Settings` and the whole :class:`ExperimentConfig`.

A new option of the experiment is a field here: the stages read it from the
config they are handed, the command line sets it, and
:meth:`ExperimentConfig.to_json` records it in ``results.json``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

__all__ = ["DEFAULT_REPLICATES", "FULL_REPLICATES", "MISMATCHES", "CONTROLS", "Settings", "ExperimentConfig"]

#: Replicates of the instance protocol in a quick run (the default) and in a full run.
DEFAULT_REPLICATES = 5
FULL_REPLICATES = 20

#: How a mismatch arm makes the test instances differ from what the training touches and codebooks simulate.
MISMATCHES = {
    "exact": "the test touches are exact plane sections (tactile.imprint_exact), the codebooks ray cast",
    "noise_half": "the test device's reading noise and gain spread are half what the codebooks assume",
    "noise_double": "the test device's reading noise and gain spread are twice what the codebooks assume",
    "decimated": "the test instances have half the faces (other vertices than training touched)",
    "subdivided": "the test instances have every face split in four",
}
#: Control runs: what should bring recognition down to chance.
CONTROLS = {
    "shuffled": "each test instance gets the imprints of another object's test instance, place for place",
    "scrambled": "each test instance gets another object's test imprints in a random order",
}


def _typical():
    import tactile

    return tactile.Perturbation.typical()


def _sensor():
    import tactile

    return tactile.Sensor()


@dataclass(frozen=True)
class Settings:
    """Everything the per-object stage depends on besides the mesh, its name and the draw.

    Attributes
    ----------
    n_points : int
        Interest points per instance.
    size_mm : float or None
        Nominal principal-frame box diagonal; None keeps the real size of
        objects whose units are known (the toys in millimetres, the YCB
        scans in metres), each instance still resized by ``scale_spread``.
    view_size : int or None
        Rendered view size for the attention method (None: its default).
    sensor : tactile.Sensor
    perturbation : tactile.Perturbation
        Of every acquisition session (default ``Perturbation.typical()``).
    train_instances : int
        Training instances per object and replicate.
    train_sessions : int
        Acquisition sessions per training instance (the test instance has one).
    scale_spread, hue_deg, brightness_spread : float
        Instance variation (``meshsal.objects.instances.draw_instance``).
    seed : int
        Base seed of every draw.
    codebook_draws : int
        Simulated touches per place and training instance in the touch
        codebooks of the place-aware recognizer (``tactile.touch_codebook``).
    mismatch : tuple of str
        A mismatch arm (:data:`MISMATCHES`, several apply together): the test
        instances and their touches depart from what training simulates.
        Training instances and their codebooks do not depend on it.

    Cache keys hold :meth:`key`; the codebooks add ``codebook_draws`` and the
    test instances ``mismatch``, so the rest is reused across them.
    """

    n_points: int = 15
    size_mm: float | None = 150.0
    view_size: int | None = None
    sensor: object = field(default_factory=_sensor)
    perturbation: object = field(default_factory=_typical)
    train_instances: int = 3
    train_sessions: int = 2
    scale_spread: float = 0.05
    hue_deg: float = 30.0
    brightness_spread: float = 0.15
    seed: int = 0
    codebook_draws: int = 8
    mismatch: tuple = ()

    def __post_init__(self):
        from meshsal.points.rules import MIN_VIEW_SIZE

        if int(self.n_points) != self.n_points or self.n_points < 1:
            raise ValueError(f"n_points must be a positive integer, got {self.n_points!r}")
        if self.view_size is not None and (int(self.view_size) != self.view_size or self.view_size < MIN_VIEW_SIZE):
            raise ValueError(f"view_size must be an integer of at least {MIN_VIEW_SIZE} pixels, got {self.view_size!r}")
        if int(self.seed) != self.seed or self.seed < 0:
            raise ValueError(f"seed must be a non-negative integer, got {self.seed!r}")
        if self.train_instances < 2:
            raise ValueError(
                f"train_instances must be at least 2 (calibration holds one out), got {self.train_instances}"
            )
        if self.train_sessions < 1:
            raise ValueError(f"train_sessions must be at least 1, got {self.train_sessions}")
        if self.size_mm is not None and not self.size_mm > 0:
            raise ValueError(f"size_mm must be positive (or None: real sizes), got {self.size_mm}")
        if int(self.codebook_draws) != self.codebook_draws or self.codebook_draws < 1:
            raise ValueError(f"codebook_draws must be a positive integer, got {self.codebook_draws!r}")
        mismatch = (self.mismatch,) if isinstance(self.mismatch, str) else tuple(self.mismatch)
        unknown = [m for m in mismatch if m not in MISMATCHES]
        if unknown:
            raise ValueError(f"unknown mismatch {', '.join(unknown)}; choose from {', '.join(MISMATCHES)}")
        if {"decimated", "subdivided"} <= set(mismatch) or {"noise_half", "noise_double"} <= set(mismatch):
            raise ValueError(f"mismatches {list(mismatch)} contradict each other: choose one of each pair")
        object.__setattr__(self, "mismatch", tuple(sorted(set(mismatch))))

    @property
    def rendered_view_size(self) -> int:
        """The size the instances' views are rendered at: ``view_size``, or the point methods' default."""
        from meshsal.points import PointOptions

        return self.view_size or PointOptions.size

    def key(self) -> str:
        """A canonical text of every field but ``codebook_draws`` and ``mismatch``, for cache keys."""
        return repr(
            [
                self.n_points,
                None if self.size_mm is None else float(self.size_mm),
                self.view_size,
                self.sensor,
                self.perturbation,
                self.train_instances,
                self.train_sessions,
                float(self.scale_spread),
                float(self.hue_deg),
                float(self.brightness_spread),
                int(self.seed),
            ]
        )

    def to_json(self) -> dict:
        """The fields as ``results.json`` records them."""
        return {
            "n_points": self.n_points,
            "size_mm": self.size_mm,
            "view_size": self.view_size,
            "sensor": repr(self.sensor),
            "perturbation": repr(self.perturbation),
            "train_instances": self.train_instances,
            "train_sessions": self.train_sessions,
            "scale_spread": self.scale_spread,
            "hue_deg": self.hue_deg,
            "brightness_spread": self.brightness_spread,
            "seed": self.seed,
            "codebook_draws": self.codebook_draws,
            "mismatch": list(self.mismatch),
        }


def _all_protocols():
    from classify.experiment.protocols import PROTOCOLS

    return PROTOCOLS


def _all_classifiers():
    from classify.recognizers.classifiers import NAMES

    return NAMES


@dataclass(frozen=True)
class ExperimentConfig:
    """Everything an experiment measures and how.

    Attributes
    ----------
    methods : tuple of str
        Interest-point methods (``meshsal.points.METHODS``).  The model
        methods ("learned", "attention_learned") fit a touch model per
        replicate on its training instances (:mod:`classify.experiment.survey`)
        and run in the instance protocol only.
    protocols : tuple of str
        Subset of ``classify.experiment.protocols.PROTOCOLS``.
    classifiers : tuple of str
        Subset of ``classify.NAMES``.  The place-aware recognizer ("place")
        needs training instances, so it runs in the instance protocol only.
    settings : Settings
        Points, sensor, perturbation, instances and seed.
    replicates : int
        Instance-protocol replicates, each with fresh instances
        (``DEFAULT_REPLICATES`` quick, ``FULL_REPLICATES`` for a full run).
    folds, repeats : int
        Paper-protocol cross-validation folds and reshuffled repeats.
    threshold : float
        NCC threshold of similarity selection.
    touch_sets_per_object : int
        Distinct touch sets per test instance and k (all of them when fewer exist).
    params : dict
        Classifier name -> parameters for ``classify.make``.
    features : {"raw", "polar"}
        What the classifiers see: raw taxels (the paper's) or roll-invariant
        polar descriptors (``tactile.features``).
    baseline : str or None
        The method others are compared with (default ``uniform`` when
        measured, else the first method); no comparison with one method.
    policies : tuple of str
        Touch policies (``classify.policies.POLICIES``) run in the sequential
        protocol on the instance protocol's instances, compared with the
        baseline method.
    stop_levels : tuple of float
        The stopping rule's thresholds: stop when the top class's calibrated
        posterior reaches p (or after the last touch); accuracy against
        touches used, for every method and policy of the instance protocol.
    control : str or None
        A control run (:data:`CONTROLS`): ``"shuffled"`` gives each test
        instance another object's test imprints, place for place,
        ``"scrambled"`` in a random order; either must bring every recognizer
        down to chance (``classify.experiment.controls``).
    """

    methods: tuple = ("attention",)
    protocols: tuple = field(default_factory=_all_protocols)
    classifiers: tuple = field(default_factory=_all_classifiers)
    settings: Settings = field(default_factory=Settings)
    replicates: int = DEFAULT_REPLICATES
    folds: int = 5
    repeats: int = 10
    threshold: float = 0.85
    touch_sets_per_object: int = 50
    params: dict = field(default_factory=dict)
    features: str = "raw"
    baseline: str | None = None
    policies: tuple = ()
    stop_levels: tuple = (0.5, 0.8, 0.9, 0.95, 0.98, 0.99, 0.995, 0.999)
    control: str | None = None

    def replace(self, **changes) -> ExperimentConfig:
        """A copy with some fields changed; an unknown field is a TypeError naming it."""
        return dataclasses.replace(self, **changes)

    def checked(self) -> ExperimentConfig:
        """The config with names checked against their registries, tuples for lists and the baseline resolved.

        Raises
        ------
        ValueError
            An unknown method, protocol, classifier or feature set, counts out
            of range, or a baseline that is not among the methods.
        """
        from classify.experiment.protocols import PROTOCOL_REGISTRY
        from classify.policies import POLICIES
        from classify.recognizers.classifiers import CLASSIFIERS
        from meshsal.points import POINT_METHODS
        from tactile.features import FEATURES

        methods, protocols = POINT_METHODS.check(self.methods), PROTOCOL_REGISTRY.check(self.protocols)
        classifiers = CLASSIFIERS.check(self.classifiers)
        if self.folds < 2:
            raise ValueError(f"folds must be at least 2, got {self.folds}")
        for name in ("repeats", "replicates", "touch_sets_per_object"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be at least 1, got {getattr(self, name)}")
        baseline = self.baseline
        if baseline is None:
            baseline = "uniform" if "uniform" in methods else methods[0]
        if baseline not in methods:
            raise ValueError(f"baseline {baseline!r} is not among the methods {list(methods)}")
        if self.features not in FEATURES:
            raise ValueError(f"unknown features {self.features!r}; choose from {', '.join(FEATURES)}")
        policies = POLICIES.check(self.policies) if self.policies else ()
        if policies and "instance" not in protocols:
            raise ValueError("touch policies run on the instance protocol's instances: add it to the protocols")
        if self.control is not None and self.control not in CONTROLS:
            raise ValueError(f"unknown control {self.control!r}; choose from {', '.join(CONTROLS)}")
        levels = tuple(float(p) for p in self.stop_levels)
        if any(not 0.0 < p <= 1.0 for p in levels):
            raise ValueError(f"stop levels must lie in (0, 1], got {list(levels)}")
        return self.replace(
            methods=methods,
            protocols=protocols,
            classifiers=classifiers,
            baseline=baseline,
            params=dict(self.params),
            policies=policies,
            stop_levels=levels,
        )

    def to_json(self) -> dict:
        """Every setting as ``results.json`` records it (with the classifiers' full parameters)."""
        from classify.recognizers.classifiers import make

        return {
            "methods": list(self.methods),
            "protocols": list(self.protocols),
            "classifiers": list(self.classifiers),
            "baseline": self.baseline if len(self.methods) > 1 else None,
            "replicates": self.replicates,
            "folds": self.folds,
            "repeats": self.repeats,
            "threshold": self.threshold,
            "touch_sets_per_object": self.touch_sets_per_object,
            "features": self.features,
            "policies": list(self.policies),
            "stop_levels": list(self.stop_levels),
            "control": self.control,
            **self.settings.to_json(),
            "classifier_params": {
                c: {k: repr(v) for k, v in make(c, **self.params.get(c, {})).get_params().items()}
                for c in self.classifiers
            },
        }
