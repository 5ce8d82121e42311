"""What touch policies know: the places of an instance, and per-object models of what a touch there feels like.

A test instance offers :class:`Places` (vision: the candidate places of
``meshsal.points.places.candidate_places`` with their positions, normals,
visual features and touchability).  Its :class:`PlaceSample` adds the
imprints its acquisition sessions give at every place, which only the
episode runner holds: a policy sees an imprint once it has touched there.

:class:`TouchKnowledge` is fitted on the training instances only
(:func:`fit_knowledge`): a classifier of single touches with the calibration
the fusion uses (``classify.recognizers.fusion``), and for every object and
trained place the calibrated posteriors of its training touches, each scored
by a classifier that never saw that touch's instance.  Those are the
per-object models a policy forecasts with: "if the object were j, touching
here would feel like one of these".

Places carry across instances through the mesh: every instance of an object
is a turned, resized, repainted copy of one nominal mesh, so a vertex id
names the same place on all of them, and under the hypothesis "the object is
j" the test instance's vertex ``v`` is object j's vertex ``v``
(:meth:`TouchKnowledge.forecast`).  The candidate places depend on the shape
alone, so training touched (nearly) the same places; a place training did
not touch takes the nearest one it did, in the object's own frame.  A scan
of a new object would need registration instead.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Places", "PlaceSample", "Forecast", "TouchKnowledge", "fit_knowledge"]


@dataclass(frozen=True, eq=False)
class Places:
    """Where a policy may touch on one instance, and what vision says of each place.

    Attributes
    ----------
    vertex_ids : (P,) int64
        The places, vertices of the instance's mesh (pool first, then mesh-saliency peaks).
    positions, normals : (P, 3) float64
        In the instance's frame; unit outward normals.
    features : (P, len(meshsal.points.learned.FEATURES)) float64
        What the 72 views see at each place.
    touchable : (P,) bool
        The pad pressed along the normal meets the place first (``meshsal.points.touch``).
    """

    vertex_ids: np.ndarray
    positions: np.ndarray
    normals: np.ndarray
    features: np.ndarray
    touchable: np.ndarray

    def __len__(self) -> int:
        return int(self.vertex_ids.size)


@dataclass(frozen=True, eq=False)
class PlaceSample:
    """An instance's :class:`Places` and the imprints its sessions give there, (sessions, P, rows, cols) float32."""

    places: Places
    imprints: np.ndarray

    def to_arrays(self) -> dict:
        p = self.places
        return {"vertex_ids": p.vertex_ids, "positions": p.positions, "normals": p.normals, "features": p.features,
                "touchable": p.touchable, "imprints": self.imprints}

    @staticmethod
    def from_arrays(a: dict) -> PlaceSample:
        return PlaceSample(Places(a["vertex_ids"], a["positions"], a["normals"], a["features"],
                                  a["touchable"].astype(bool)), a["imprints"])


@dataclass(frozen=True, eq=False)
class Forecast:
    """What a touch at each of an instance's places would feel like under each hypothesis.

    ``posteriors`` (J, P, S, C): for hypothesis j (the object is class j),
    place p and training touch s, the calibrated posterior that touch gave;
    ``weights`` (J, P, S) the weight of each touch (summing to 1 over s, or
    0 where object j cannot have the place: its rows are then uniform).
    """

    posteriors: np.ndarray
    weights: np.ndarray
    #: ``posteriors * log(posteriors)``: the part of an entropy that does not depend on the belief (derived).
    plogp: np.ndarray = None

    def __post_init__(self):
        object.__setattr__(self, "plogp", self.posteriors * np.log(self.posteriors))


@dataclass(frozen=True, eq=False)
class TouchKnowledge:
    """Per-object touch models and a calibrated single-touch classifier, fitted on training instances.

    Attributes
    ----------
    names : tuple of str
        The classes, in label order.
    vertices : tuple of (n_j, 3) float64
        Each object's nominal mesh vertices (the frame places are matched in).
    place_ids : tuple of (P_j,) int64
        The places each object's training instances were touched at.
    posteriors : tuple of (P_j, S, C) float64
        Calibrated held-out posteriors of those touches (a touch scored by a
        classifier fitted without its instance).
    weights : tuple of (P_j, S) float64
        Weight of each touch in its place's forecast (0 for padding).
    model : fitted classifier of single touches (all training touches)
    calibration : classify.recognizers.fusion.Calibration
    features : str
        What the classifier sees (``tactile.features.describe``).
    """

    names: tuple
    vertices: tuple
    place_ids: tuple
    posteriors: tuple
    weights: tuple
    model: object
    calibration: object
    features: str

    @property
    def n_classes(self) -> int:
        return len(self.names)

    def posterior(self, imprints: np.ndarray) -> np.ndarray:
        """(k, C) calibrated posteriors of single touches' imprints (k, rows, cols)."""
        from classify.recognizers.fusion import calibrate
        from classify.recognizers.touches import posteriors
        from tactile.features import describe

        if len(imprints) == 0:
            return np.zeros((0, self.n_classes))
        return calibrate(posteriors(self.model, describe(imprints, self.features), self.n_classes), self.calibration)

    def match(self, j: int, vertex_ids: np.ndarray) -> np.ndarray:
        """The trained place of object ``j`` each vertex would be if the object were j, (P,) int64 (-1: none).

        Under "the object is j" an instance's vertex ``v`` is j's vertex ``v``;
        its trained place is the one nearest to that vertex in j's frame (the
        vertex itself when training touched it).
        """
        from scipy.spatial import cKDTree

        ids = np.asarray(vertex_ids, dtype=np.int64)
        out = np.full(ids.size, -1, np.int64)
        mine = ids < len(self.vertices[j])
        if mine.any():
            out[mine] = cKDTree(self.vertices[j][self.place_ids[j]]).query(self.vertices[j][ids[mine]])[1]
        return out

    def forecast(self, vertex_ids: np.ndarray) -> Forecast:
        """The :class:`Forecast` of an instance's places, given as vertex ids of its mesh."""
        ids = np.asarray(vertex_ids, dtype=np.int64)
        C = self.n_classes
        S = max(w.shape[1] for w in self.weights)
        out = np.full((C, ids.size, S, C), 1.0 / C)
        weight = np.zeros((C, ids.size, S))
        for j in range(C):
            place = self.match(j, ids)
            mine = place >= 0
            s = self.posteriors[j].shape[1]
            out[j, mine, :s] = self.posteriors[j][place[mine]]
            weight[j, mine, :s] = self.weights[j][place[mine]]
        return Forecast(out, weight)


def fit_knowledge(training: dict, nominal_vertices: dict, recognizer) -> TouchKnowledge:
    """Touch knowledge from training instances' place samples.

    Parameters
    ----------
    training : dict (object name, instance index) -> PlaceSample
        Training instances only (index >= 1); every session of every place is a training touch.
    nominal_vertices : dict object name -> (n, 3) float64, the object's nominal mesh vertices
    recognizer : classify.recognizers.touches.Recognizer
        The single-touch classifier (selection is not applied: every place counts).

    Returns
    -------
    TouchKnowledge, classes in the order of the sorted object names
    """
    from classify.recognizers.fusion import calibrate, fit_calibration
    from classify.recognizers.touches import point_groups, posteriors
    from tactile.features import describe

    names = tuple(sorted({name for name, _ in training}))
    if len(names) < 2 or any(j < 1 for _, j in training):
        raise ValueError(f"touch knowledge needs training instances (index >= 1) of at least two objects, "
                         f"got {sorted(training)}")
    keys = sorted(training, key=lambda k: (names.index(k[0]), k[1]))
    X, y, inst, vertex = [], [], [], []
    for name, j in keys:
        sample = training[name, j]
        sessions, P = sample.imprints.shape[:2]
        X.append(sample.imprints.reshape(-1, *sample.imprints.shape[2:]))
        y.append(np.full(sessions * P, names.index(name)))
        inst.append(np.full(sessions * P, j))
        vertex.append(np.tile(sample.places.vertex_ids, sessions))
    X, y, inst, vertex = (np.concatenate(a) for a in (X, y, inst, vertex))
    F = describe(X, recognizer.features)
    groups = point_groups(y, vertex, inst)
    C = len(names)
    held = np.zeros((len(y), C))
    for i in np.unique(inst):
        out = inst == i
        model = recognizer.fit(F[~out], y[~out], groups[~out])
        held[out] = posteriors(model, F[out], C)
    calibration = fit_calibration(held, y)
    held = calibrate(held, calibration)
    model = recognizer.fit(F, y, groups)
    place_ids, posteriors, weights = [], [], []
    for c in range(len(names)):
        mine = y == c
        ids, where = np.unique(vertex[mine], return_inverse=True)
        counts = np.bincount(where, minlength=ids.size)
        S = int(counts.max())
        post = np.full((ids.size, S, C), 1.0 / C)
        weight = np.zeros((ids.size, S))
        slot = np.zeros(ids.size, np.int64)
        for row, p in zip(held[mine], where):
            post[p, slot[p]] = row
            weight[p, slot[p]] = 1.0 / counts[p]
            slot[p] += 1
        place_ids.append(ids)
        posteriors.append(post)
        weights.append(weight)
    vertices = tuple(np.asarray(nominal_vertices[name], dtype=np.float64) for name in names)
    return TouchKnowledge(names, vertices, tuple(place_ids), tuple(posteriors), tuple(weights), model, calibration,
                          recognizer.features)
