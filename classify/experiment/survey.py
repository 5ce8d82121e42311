"""Learning where to touch: each instance's touch survey, how distinctive each surveyed touch is, the model.

In each replicate of the instance protocol, every training instance's
candidate pool is touched once (:func:`touch_survey`).  A
touch is distinctive when its imprint lies nearer the same object's touches
than any other object's, on the *other* training instances:
:func:`distinctiveness` is that leave-the-instance-out nearest-neighbour
margin.  :func:`fit_replicate_model` regresses it on the candidates' visual
features (``meshsal.points.learned.fit_touch_model``).  Test instances never enter:
their surveys carry no touches, and the fit takes training instances only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Survey", "touch_survey", "distinctiveness", "fit_replicate_model"]


@dataclass(frozen=True, eq=False)
class Survey:
    """What the learned methods know of one instance.

    ``pool`` (P,) int64 candidate vertex ids (``meshsal.points.learned.candidate_pool``);
    ``features`` (P, len(meshsal.points.learned.FEATURES)) float64, what vision
    sees at each; ``descriptors`` (P, d) float32, the roll-invariant polar
    descriptors of one touch of each, on a training instance only (None on
    the test instance, which is never touched here); ``vertex_saliency``
    (n_vertices,) float64, the instance's mesh saliency, which the learned
    methods' fill reads, so that choosing from the survey needs no mesh
    saliency computed again (None: computed when needed).
    """

    pool: np.ndarray
    features: np.ndarray
    descriptors: np.ndarray | None = None
    vertex_saliency: np.ndarray | None = None

    def to_arrays(self) -> dict:
        arrays = {
            "pool": self.pool,
            "features": self.features,
            "descriptors": self.descriptors,
            "vertex_saliency": self.vertex_saliency,
        }
        return {name: a for name, a in arrays.items() if a is not None}

    @staticmethod
    def from_arrays(arrays: dict) -> Survey:
        return Survey(arrays["pool"], arrays["features"], arrays.get("descriptors"), arrays.get("vertex_saliency"))


def touch_survey(
    mesh, pool, features, settings, scene, rng: np.random.Generator | None = None, vertex_saliency=None
) -> Survey:
    """One instance's candidate pool and their visual features; with ``rng``, one touch of each.

    Parameters
    ----------
    mesh : meshsal.Mesh, the instance
    pool : (P,) int, ``meshsal.points.places.candidate_pool`` of the instance
    features : (P, len(meshsal.points.learned.FEATURES)) float64, ``point_features`` of the pool
    settings : classify.experiment.config.Settings
    scene : Embree scene of ``mesh``
    rng : numpy Generator, optional
        The survey stream of a *training* instance: the pool is touched once
        (its own device and rolls) and the imprints' roll-invariant polar
        descriptors kept, on which the distinctiveness of each candidate is
        measured.  None for the test instance, which is never touched here.
    """
    import tactile
    from meshsal.mesh import vertex_normals
    from tactile.features import describe

    pool = np.asarray(pool, np.int64)
    features = np.asarray(features, np.float64)
    if rng is None:
        return Survey(pool, features, vertex_saliency=vertex_saliency)
    vn = vertex_normals(mesh.vertices, mesh.faces)
    images = tactile.acquire(
        mesh, mesh.vertices[pool], vn[pool], settings.sensor, settings.perturbation, rng, scene=scene
    )
    descriptors = describe(np.asarray(images, np.float32), "polar").astype(np.float32)
    return Survey(pool, features, descriptors, vertex_saliency)


def distinctiveness(
    descriptors: np.ndarray, labels: np.ndarray, instances: np.ndarray, chunk: int = 1024
) -> np.ndarray:
    """Leave-the-instance-out nearest-neighbour margin of each touch.

    With ``d_same`` the distance to the nearest touch of the same object on
    another instance and ``d_other`` the distance to the nearest touch of
    another object, the margin is ``(d_other - d_same) / (d_other + d_same)``
    in [-1, 1]: 1 when the touch is recognized with room to spare, below 0
    when a 1-NN would get it wrong.

    Parameters
    ----------
    descriptors : (m, d) float
    labels : (m,) int, object of each touch
    instances : (m,) int, instance of each touch; rows of one (label, instance) never compare
    chunk : rows per block of distances

    Returns
    -------
    (m,) float64; 0 where a touch has no same-object or no other-object reference

    Examples
    --------
    >>> D = np.array([[0.0], [0.1], [5.0], [5.1]])
    >>> distinctiveness(D, np.array([0, 0, 1, 1]), np.array([1, 2, 1, 2])).round(3).tolist()
    [0.961, 0.96, 0.96, 0.961]
    """
    X = np.asarray(descriptors, dtype=np.float64)
    y = np.asarray(labels, dtype=np.int64)
    inst = np.asarray(instances, dtype=np.int64)
    if X.ndim != 2 or y.shape != (X.shape[0],) or inst.shape != y.shape:
        raise ValueError(
            f"expected descriptors (m, d) with m labels and instances, got {X.shape}, {y.shape}, {inst.shape}"
        )
    norms = np.einsum("ij,ij->i", X, X)
    out = np.zeros(len(y))
    for start in range(0, len(y), chunk):
        rows = slice(start, start + chunk)
        d2 = np.maximum(norms[rows, None] + norms[None, :] - 2.0 * X[rows] @ X.T, 0.0)
        own = (y[rows, None] == y[None, :]) & (inst[rows, None] == inst[None, :])
        same = np.where((y[rows, None] == y[None, :]) & ~own, d2, np.inf).min(axis=1)
        other = np.where(y[rows, None] != y[None, :], d2, np.inf).min(axis=1)
        ok = np.isfinite(same) & np.isfinite(other)
        d_same, d_other = np.sqrt(same[ok]), np.sqrt(other[ok])
        total = d_same + d_other
        out[np.arange(len(y))[rows][ok]] = np.where(total > 0, (d_other - d_same) / np.maximum(total, 1e-300), 0.0)
    return out


def fit_replicate_model(surveys: dict, alpha: float = 1.0, view_size: int | None = None):
    """The touch model of one replicate, from its training instances' surveys.

    Parameters
    ----------
    surveys : dict (object name, instance index) -> Survey
        As made by :func:`touch_survey`.  Instance 0 (the test instance) is
        ignored whatever it holds.
    alpha : ridge penalty (``meshsal.points.learned.fit_touch_model``)
    view_size : the size the surveys' views were rendered at, recorded in the model

    Returns
    -------
    meshsal.points.learned.TouchModel, ``trained_on`` the ``"name/instance"`` of every survey it used
    """
    from meshsal.points.learned import fit_touch_model

    used = sorted(key for key in surveys if key[1] >= 1)
    names = sorted({name for name, _ in used})
    if len(names) < 2:
        raise ValueError(f"a touch model needs training instances of at least two objects, got {names}")
    label = {name: c for c, name in enumerate(names)}
    features, descriptors, labels, instances = [], [], [], []
    for name, j in used:
        survey = surveys[name, j]
        features.append(survey.features)
        descriptors.append(survey.descriptors)
        labels.append(np.full(len(survey.features), label[name]))
        instances.append(np.full(len(survey.features), j))
    margin = distinctiveness(np.concatenate(descriptors), np.concatenate(labels), np.concatenate(instances))
    trained_on = tuple(f"{name}/{j}" for name, j in used)
    return fit_touch_model(np.concatenate(features), margin, alpha, trained_on=trained_on, view_size=view_size)
