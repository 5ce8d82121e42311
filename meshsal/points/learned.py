"""A learned touch saliency: per-point visual features, and a model of how distinctive a touch there is.

The paper ranks points by visual attention alone.  Whether a touch at a
point helps recognition is measurable, though: on training objects, touch
candidate points and see how well their imprints tell the object apart
(``classify.experiment.survey.distinctiveness``).  This module holds the vision side:

* :func:`~meshsal.points.places.candidate_pool`: the points a learned method
  may choose from, farthest-point samples spread over the whole surface, the
  same on every instance of an object;
* :func:`point_features`: what vision knows about each candidate, the
  ``FEATURES``: the eight channel values averaged over the views that see
  it, how many views see it, its attention votes, its mesh saliency and
  its absolute mean curvature;
* :class:`TouchModel` and :func:`fit_touch_model`: a ridge regression from
  standardized features to distinctiveness (scikit-learn's ``StandardScaler``
  and ``Ridge``), plus the channel weights of the
  paper's combination that best predict it (non-negative least squares,
  mean 1, so equal weights are all ones).

Nothing here sees an imprint or a label: the target comes from the caller,
which decides what the model is trained on (``TouchModel.trained_on``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from meshsal.attention import CHANNELS
from meshsal.mesh import Mesh, vertex_normals
from meshsal.mesh.curvature import mean_curvature
from meshsal.mesh.geometry import edge_graph
from meshsal.points.attend import check_field, salient_vertices, view_votes
from meshsal.points.places import POOL_FACTOR, candidate_pool
from meshsal.points.record import InterestPoints
from meshsal.points.rules import PointOptions, Rules
from meshsal.points.select import choose_without_views, vertex_candidates

__all__ = [
    "FEATURES",
    "POOL_FACTOR",
    "candidate_pool",
    "point_features",
    "TouchModel",
    "fit_touch_model",
    "learned_points",
]

#: The per-point visual features, in column order.
FEATURES = tuple(f"{c}_mean" for c in CHANNELS) + ("views", "votes", "mesh_saliency", "curvature")
MODEL_FORMAT = "visuotactile.touch_model"
MODEL_VERSION = 1


def _channel_means(mesh: Mesh, views, results, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """At vertices ``ids`` (k,): each channel's mean over the pixels of their faces in the views that see them
    (len(CHANNELS), k), and how many views see them (k,)."""
    unique, back = np.unique(ids, return_inverse=True)
    k = unique.size
    # Only the pixels of faces around the asked vertices count: each vertex's sums take the same terms in the
    # same order as over the whole mesh, at a fraction of the cost.
    slot = np.full(mesh.n_vertices, -1, np.int64)
    slot[unique] = np.arange(k)
    sums = np.zeros((len(CHANNELS), k))
    pixels = np.zeros(k)
    seen = np.zeros(k)
    for view, result in zip(views, results):
        hit = np.flatnonzero(view.mask)
        corners = slot[mesh.faces[view.face_id.reshape(-1)[hit]]].ravel()
        near = np.flatnonzero(corners >= 0)
        corners = corners[near]
        counts = np.bincount(corners, minlength=k)
        pixels += counts
        seen += counts > 0
        # The pixel of each corner kept (three corners a pixel): each channel is read there only.
        at = hit[near // 3]
        for c, name in enumerate(CHANNELS):
            values = result.channels[name].reshape(-1)[at].astype(np.float64)
            sums[c] += np.bincount(corners, weights=values, minlength=k)
    return (sums / np.maximum(pixels, 1.0))[:, back], seen[back]


def point_features(
    mesh: Mesh,
    views,
    results,
    maps: np.ndarray,
    vertex_saliency: np.ndarray,
    vertex_ids: np.ndarray,
    spacing: float,
    threshold: float = 0.5,
) -> np.ndarray:
    """The ``FEATURES`` of some vertices, from the 72 views and their channels.

    Parameters
    ----------
    mesh : Mesh
    views : list of View
    results : list of meshsal.attention.SaliencyResult, one per view (their ``channels`` are used)
    maps : (len(views), H, W) float32
        Combined saliency maps, for the votes (as in :func:`meshsal.points.attend.attention_points`).
    vertex_saliency : (n_vertices,) float64
    vertex_ids : (k,) int
    spacing : float
        Vote radius along mesh edges, mesh units.
    threshold : float
        Salient pixels exceed ``threshold`` times their map's maximum.

    Returns
    -------
    (k, len(FEATURES)) float64
    """
    ids = np.asarray(vertex_ids, dtype=np.int64)
    means, seen = _channel_means(mesh, views, results, ids)
    votes, _ = view_votes(
        edge_graph(mesh.vertices, mesh.faces), salient_vertices(mesh, views, maps, threshold), ids, spacing
    )
    curvature = np.abs(mean_curvature(mesh.vertices, mesh.faces))[ids]
    columns = [
        means.T,
        seen[:, None],
        votes[:, None].astype(np.float64),
        np.asarray(vertex_saliency, np.float64)[ids, None],
        curvature[:, None],
    ]
    return np.concatenate(columns, axis=1)


@dataclass(frozen=True, eq=False)
class TouchModel:
    """Predicted touch distinctiveness from ``FEATURES``, and learned channel weights.

    Attributes
    ----------
    mean, scale : (len(FEATURES),) float64
        Standardization of the features (training mean and standard deviation).
    coef : (len(FEATURES),) float64
        Ridge coefficients on standardized features.
    intercept : float
    channel_weights : dict channel name -> float
        Non-negative weights of the eight channels for
        ``meshsal.attention.combine_maps`` (mean 1).
    trained_on : tuple of str
        What the training rows came from, as the caller labelled them.
    view_size : int or None
        The rendered view size (pixels) its features were measured at, when
        known: the channel means change with it, so the model is meant for
        views of that size.
    """

    mean: np.ndarray
    scale: np.ndarray
    coef: np.ndarray
    intercept: float
    channel_weights: dict
    trained_on: tuple = ()
    view_size: int | None = None

    def predict(self, features: np.ndarray) -> np.ndarray:
        """(k,) predicted distinctiveness of (k, len(FEATURES)) features."""
        X = np.asarray(features, dtype=np.float64)
        if X.ndim != 2 or X.shape[1] != len(FEATURES):
            raise ValueError(f"features must have shape (k, {len(FEATURES)}), got {X.shape}")
        return (X - self.mean) / self.scale @ self.coef + self.intercept

    def save(self, path) -> None:
        """Write the model as a versioned JSON file, atomically.

        Examples
        --------
        >>> import pathlib, tempfile
        >>> rng = np.random.default_rng(0)
        >>> model = fit_touch_model(rng.random((50, len(FEATURES))), rng.random(50))
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "touch_model.json"
        >>> model.save(path)
        >>> again = TouchModel.load(path)
        >>> bool(np.allclose(again.predict(np.ones((1, len(FEATURES)))), model.predict(np.ones((1, len(FEATURES))))))
        True
        """
        import json

        from meshsal.util.atomic import write_text

        document = {
            "format": MODEL_FORMAT,
            "version": MODEL_VERSION,
            "features": list(FEATURES),
            "mean": self.mean.tolist(),
            "scale": self.scale.tolist(),
            "coef": self.coef.tolist(),
            "intercept": self.intercept,
            "channel_weights": self.channel_weights,
            "trained_on": list(self.trained_on),
            "view_size": self.view_size,
        }
        write_text(path, json.dumps(document, indent=1) + "\n")

    @staticmethod
    def load(path) -> TouchModel:
        """Read a model written by :meth:`save`; a clear error names the file and what is wrong."""
        from meshsal.util.jsonfile import read_json

        document = read_json(path, "touch model file")
        if not isinstance(document, dict) or document.get("format") != MODEL_FORMAT:
            raise ValueError(f"{path}: not a touch model file (format {MODEL_FORMAT!r} expected)")
        if document.get("version") != MODEL_VERSION or document.get("features") != list(FEATURES):
            raise ValueError(
                f"{path}: a touch model of version {document.get('version')!r} with features "
                f"{document.get('features')}; this reads version {MODEL_VERSION} with {list(FEATURES)}"
            )
        try:
            arrays = [np.asarray(document[k], dtype=np.float64) for k in ("mean", "scale", "coef")]
            weights = {str(k): float(v) for k, v in document["channel_weights"].items()}
            intercept = float(document["intercept"])
            view_size = document.get("view_size")  # optional: a model file need not record it
            view_size = None if view_size is None else int(view_size)
        except (KeyError, TypeError, ValueError, AttributeError) as error:
            raise ValueError(f"{path}: incomplete or malformed touch model ({error})") from None
        if (
            any(a.shape != (len(FEATURES),) or not np.isfinite(a).all() for a in arrays)
            or not (arrays[1] > 0).all()
            or sorted(weights) != sorted(CHANNELS)
        ):
            raise ValueError(
                f"{path}: malformed touch model (mean, scale, coef must be {len(FEATURES)} finite "
                f"numbers, scale positive; channel_weights one per channel)"
            )
        trained_on = tuple(str(t) for t in document.get("trained_on", ()))
        return TouchModel(*arrays, intercept, weights, trained_on, view_size)


def fit_touch_model(
    features: np.ndarray, target: np.ndarray, alpha: float = 1.0, trained_on: tuple = (), view_size: int | None = None
) -> TouchModel:
    """Ridge regression of ``target`` on standardized ``features``; NNLS channel weights.

    Parameters
    ----------
    features : (m, len(FEATURES)) float
    target : (m,) float, e.g. a leave-instance-out kNN margin
    alpha : float >= 0
        Ridge penalty (per row: the penalty is ``alpha * m``).
    trained_on : tuple of str
        Recorded in the model.
    view_size : int, optional
        The view size the features were measured at, recorded in the model.

    Returns
    -------
    TouchModel

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> X = rng.random((200, len(FEATURES)))
    >>> model = fit_touch_model(X, 3.0 * X[:, 2])            # distinctiveness follows the third channel
    >>> max(model.channel_weights, key=model.channel_weights.get) == CHANNELS[2]
    True
    """
    from scipy.optimize import nnls
    from sklearn.linear_model import Ridge
    from sklearn.preprocessing import StandardScaler

    X = np.asarray(features, dtype=np.float64)
    y = np.asarray(target, dtype=np.float64)
    if X.ndim != 2 or X.shape[1] != len(FEATURES):
        raise ValueError(f"features must have shape (m, {len(FEATURES)}), got {X.shape}")
    if y.shape != (X.shape[0],):
        raise ValueError(f"target must have shape ({X.shape[0]},), got {y.shape}")
    if X.shape[0] < 2:
        raise ValueError(f"a touch model needs at least 2 training points, got {X.shape[0]}")
    if not (np.isfinite(X).all() and np.isfinite(y).all()):
        raise ValueError("features and target must be finite")
    if not alpha >= 0:
        raise ValueError(f"alpha must be >= 0, got {alpha}")
    scaler = StandardScaler().fit(X)
    ridge = Ridge(alpha=alpha * len(y)).fit(scaler.transform(X), y)
    # The combination sums channels scaled to [0, 1]: their raw values, centred, with non-negative weights.
    C = X[:, : len(CHANNELS)] - X[:, : len(CHANNELS)].mean(axis=0)
    w, _ = nnls(C, y - y.mean())
    w = np.ones(len(CHANNELS)) if not w.sum() > 0 else w * len(CHANNELS) / w.sum()
    return TouchModel(
        scaler.mean_,
        scaler.scale_,
        ridge.coef_,
        float(ridge.intercept_),
        dict(zip(CHANNELS, w.tolist())),
        tuple(trained_on),
        None if view_size is None else int(view_size),
    )


def learned_points(
    mesh: Mesh,
    pool: np.ndarray,
    features: np.ndarray,
    model: TouchModel,
    vertex_saliency: np.ndarray,
    rules: Rules | None = None,
    scene=None,
    touch=None,
    **changes,
) -> InterestPoints:
    """The "learned" method on a candidate pool whose features are known.

    Candidates are ranked by ``model.predict(features)`` (ties by pool
    order), then chosen under the same spacing and touch rules as every
    method, with the same mesh-saliency fill.

    Parameters
    ----------
    mesh : Mesh
    pool : (k,) int vertex ids (:func:`candidate_pool`)
    features : (k, len(FEATURES)) float (:func:`point_features`)
    model : TouchModel
    vertex_saliency : (n_vertices,) float64
    rules : Rules, optional
        Default ``PointOptions(**changes).rules(mesh)`` (``n``, ``min_spacing``, ``pad_width``, ``touch``,
        ``touch_tolerance``).
    scene, touch : optional
        As in :func:`meshsal.points.select.choose_without_views`.

    Returns
    -------
    InterestPoints (``scores`` the predicted distinctiveness; filled points score below every pool point)
    """
    rules = PointOptions(**changes).rules(mesh) if rules is None else rules
    vertex_saliency = check_field(mesh, vertex_saliency)
    pool = np.asarray(pool, dtype=np.int64)
    predicted = np.asarray(model.predict(features), dtype=np.float64)
    if predicted.shape != pool.shape:
        raise ValueError(f"{pool.size} pool vertices but {predicted.size} rows of features")
    order = np.lexsort((np.arange(pool.size), -predicted))
    vn = vertex_normals(mesh.vertices, mesh.faces)
    floor = float(predicted.min()) - 1.0 if predicted.size else 0.0
    first = vertex_candidates(mesh, vn, pool[order], predicted[order])
    return choose_without_views(
        mesh, vn, vertex_saliency, first, lambda i: np.full(i.size, floor), rules, "learned", scene, touch
    )
