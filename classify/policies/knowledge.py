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

Places carry across instances by where they lie on the shape.  The candidate
places start with a farthest-point pool from the vertex farthest from the
centroid, which depends on the shape alone, so its first :data:`LANDMARKS`
places are the same places of every turned, resized, repainted instance of
an object.  Each place is located by its :func:`signatures`, its distances to
those landmarks over the distance of the first two: invariant to the pose
and the size.  Under the hypothesis "the object is j" a place of the test
instance is the trained place of j with the nearest signature
(:meth:`TouchKnowledge.match`): the very same place when the object is j,
whatever order the mesh-saliency peaks came in.  Everything in it is
computed from the instance's own geometry, as a robot would compute it from
a scan: nothing of the object's identity (its nominal mesh, its vertex
numbering, its pose) enters the correspondence.  Where a shape is symmetric
the landmarks, and so the places, are defined only up to its symmetry (a
ball's pool starts anywhere), which is what a touch can tell apart anyway.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from classify.recognizers.distances import LEVELS
from classify.recognizers.shortlist import SHORTLIST
from meshsal.points.places import LANDMARKS

__all__ = [
    "LANDMARKS",
    "Places",
    "PlaceSample",
    "PackedPlaceSample",
    "Forecast",
    "TouchKnowledge",
    "signatures",
    "fit_knowledge",
]


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
    frame : meshsal.points.frames.ShapeFrame or None
        The instance's surface frame (``meshsal.points.frames.shape_frame``):
        how another object's landmarks are laid onto it without registering
        it (``classify.policies.place_knowledge``).  None where no mesh gave one.
    """

    vertex_ids: np.ndarray
    positions: np.ndarray
    normals: np.ndarray
    features: np.ndarray
    touchable: np.ndarray
    frame: object = None

    def __len__(self) -> int:
        return int(self.vertex_ids.size)

    def to_arrays(self) -> dict:
        arrays = {
            "vertex_ids": self.vertex_ids,
            "positions": self.positions,
            "normals": self.normals,
            "features": self.features,
            "touchable": self.touchable,
        }
        if self.frame is not None:
            arrays["frame"] = self.frame.to_array()
        return arrays

    @staticmethod
    def from_arrays(a: dict) -> Places:
        from meshsal.points.frames import ShapeFrame

        frame = ShapeFrame.from_array(a["frame"]) if "frame" in a else None
        return Places(a["vertex_ids"], a["positions"], a["normals"], a["features"], a["touchable"].astype(bool), frame)


@dataclass(frozen=True, eq=False)
class PlaceSample:
    """An instance's :class:`Places` and the imprints its sessions give there, (sessions, P, rows, cols) float32.

    ``codebook`` (P, draws, d) float32, on a training instance of a run with
    the place-aware recognizer: the polar descriptors of many simulated
    touches at each touchable place (``tactile.touch_codebook``; zeros at
    places no pad can touch).  It is stored apart from the rest.
    """

    places: Places
    imprints: np.ndarray
    codebook: np.ndarray | None = None

    def to_arrays(self) -> dict:
        return {**self.places.to_arrays(), "imprints": self.imprints}

    @staticmethod
    def from_arrays(a: dict) -> PlaceSample:
        return PlaceSample(Places.from_arrays(a), a["imprints"])

    @property
    def landmarks(self) -> np.ndarray:
        """(LANDMARKS, 3) the instance's first pool places, which locate any point on it (``signatures``)."""
        return self.places.positions[:LANDMARKS]

    def packed(self):
        """A :class:`PackedPlaceSample` when the imprints are exactly an 8-bit ADC's readings, else this sample."""
        codes = _adc_codes(self.imprints)
        return self if codes is None else PackedPlaceSample(self.places, codes, self.codebook)

    def unpacked(self) -> PlaceSample:
        """This sample (see :meth:`PackedPlaceSample.unpacked`)."""
        return self

    def in_memory(self) -> PlaceSample:
        """This sample: its arrays are in memory (a sample an experiment stored on disk reads them)."""
        return self

    def without_codebook(self) -> PlaceSample:
        return replace(self, codebook=None)


@dataclass(frozen=True, eq=False)
class PackedPlaceSample:
    """A :class:`PlaceSample` whose imprints an 8-bit ADC read, held as their uint8 codes: a quarter of the bytes.

    An experiment holds every instance's places at once and sends each job
    all of a replicate's: packed, they take a third less memory and
    pickle.  ``imprints`` and :meth:`unpacked` give the float32 readings
    back, bit for bit.
    """

    places: Places
    codes: np.ndarray
    codebook: np.ndarray | None = None

    @property
    def imprints(self) -> np.ndarray:
        return _readings(self.codes)

    @property
    def landmarks(self) -> np.ndarray:
        return self.places.positions[:LANDMARKS]

    def to_arrays(self) -> dict:
        return self.unpacked().to_arrays()

    def unpacked(self) -> PlaceSample:
        """The :class:`PlaceSample`, its imprints as float32 readings."""
        return PlaceSample(self.places, self.imprints, self.codebook)

    def in_memory(self) -> PackedPlaceSample:
        return self

    def without_codebook(self) -> PackedPlaceSample:
        return replace(self, codebook=None)


def _adc_codes(imprints) -> np.ndarray | None:
    """The uint8 codes of float32 imprints that are exactly an 8-bit ADC's readings (``k / LEVELS``), else None."""
    a = np.ascontiguousarray(imprints)
    if a.dtype != np.float32 or not a.size:
        return None
    codes = np.rint(a * np.float32(LEVELS))
    if not (codes.min() >= 0.0 and codes.max() <= LEVELS):  # also False with a NaN
        return None
    codes = codes.astype(np.uint8)
    return codes if np.array_equal(_readings(codes).view(np.int32), a.view(np.int32)) else None


def _readings(codes: np.ndarray) -> np.ndarray:
    """float32 readings of uint8 ADC codes, rounded as the ADC rounds them (``tactile.perturbation``)."""
    return (codes / LEVELS).astype(np.float32)


def signatures(places: Places, positions=None) -> np.ndarray:
    """Where each place lies on its shape, whatever the pose and size: (P, LANDMARKS) float64; or where
    ``positions`` (k, 3) on the instance of ``places`` lie, (k, LANDMARKS).

    ``meshsal.points.places.signatures`` of the places (or the positions)
    against the places' own first :data:`LANDMARKS` (the start of the
    shape-determined pool).

    Examples
    --------
    >>> X = np.array([[0.0, 0, 0], [10, 0, 0], [0, 5, 0]])
    >>> line = Places(np.arange(3), X, np.tile([0.0, 0, 1], (3, 1)), np.zeros((3, 1)), np.ones(3, bool))
    >>> signatures(line).round(3).tolist()[2]
    [0.5, 1.118, 0.0]
    """
    from meshsal.points.places import signatures as located

    return located(places.positions if positions is None else positions, places.positions[:LANDMARKS])


@dataclass(frozen=True, eq=False)
class Forecast:
    """What a touch at each of an instance's places would feel like under each hypothesis.

    ``posteriors`` (J, P, S, J): for hypothesis j (the object is class
    ``classes[j]``), place p and training touch s, the calibrated posterior
    that touch gave over the hypotheses; ``weights`` (J, P, S) the weight of
    each touch (summing to 1 over s, or 0 where object j cannot have the
    place: its rows are then uniform); ``classes`` (J,) int64 the hypotheses,
    None for every object in order.
    """

    posteriors: np.ndarray
    weights: np.ndarray
    classes: np.ndarray | None = None
    #: ``posteriors * log(posteriors)``, 0 where a posterior is 0 (its limit): the part of an entropy that does not
    #: depend on the belief (derived).
    plogp: np.ndarray = None

    def __post_init__(self):
        p = self.posteriors
        with np.errstate(divide="ignore", invalid="ignore"):
            object.__setattr__(self, "plogp", np.where(p > 0, p * np.log(p), 0.0))


@dataclass(frozen=True, eq=False)
class TouchKnowledge:
    """Per-object touch models and a calibrated single-touch classifier, fitted on training instances.

    Attributes
    ----------
    names : tuple of str
        The classes, in label order.
    place_ids : tuple of (P_j,) int64
        The places (vertex ids) each object's training instances were touched at.
    signatures : tuple of (P_j, LANDMARKS) float64
        Where each of those places lies on its object (:func:`signatures`).
    posteriors : tuple of classify.recognizers.shortlist.SparseRows (P_j, S)
        Calibrated held-out posteriors of those touches (a touch scored by a
        classifier fitted without its instance): every object's up to
        :attr:`hypotheses` objects, past it each row's most probable ones.
    weights : tuple of (P_j, S) float64
        Weight of each touch in its place's forecast (0 for padding).
    model : fitted classifier of single touches (all training touches)
    calibration : classify.recognizers.fusion.Calibration
    features : str
        What the classifier sees (``tactile.features.describe``).
    """

    names: tuple
    place_ids: tuple
    signatures: tuple
    posteriors: tuple
    weights: tuple
    model: object
    calibration: object
    features: str

    @property
    def n_classes(self) -> int:
        return len(self.names)

    def posterior(self, imprints: np.ndarray, places: Places | None = None) -> np.ndarray:
        """(k, C) calibrated posteriors of single touches' imprints (k, rows, cols); where they were taken
        (``places``) is not used: this knowledge is place-free."""
        from classify.recognizers.fusion import calibrate
        from classify.recognizers.touches import posteriors
        from tactile.features import describe

        if len(imprints) == 0:
            return np.zeros((0, self.n_classes))
        return calibrate(posteriors(self.model, describe(imprints, self.features), self.n_classes), self.calibration)

    def posterior_at(self, imprints: np.ndarray, positions, places: Places | None = None) -> np.ndarray:
        """(k, C) as :meth:`posterior`: where the touches were taken is not used."""
        return self.posterior(imprints, places)

    def match(self, j: int, places: Places) -> np.ndarray:
        """The trained place of object ``j`` each of an instance's places would be if the object were j.

        Returns (P,) int64 indices into ``place_ids[j]``: the trained place with the nearest signature.
        """
        from scipy.spatial import cKDTree

        return cKDTree(self.signatures[j]).query(signatures(places))[1].astype(np.int64)

    #: Hypotheses a forecast holds at most (``classify.policies.policy.hypotheses``).
    hypotheses = SHORTLIST
    #: :meth:`posterior` reads the imprints only: touches of many instances are scored in one batch
    #: (``classify.policies.episodes.Felt.feel``).
    place_free = True

    def forecast(self, places: Places, classes=None) -> Forecast:
        """The :class:`Forecast` of an instance's candidate places under ``classes`` (default: every object)."""
        C, P = self.n_classes, len(places)
        J = np.arange(C) if classes is None else np.asarray(classes, np.int64)
        S = max(w.shape[1] for w in self.weights)
        out = np.full((J.size, P, S, J.size), 1.0 / J.size)
        weight = np.zeros((J.size, P, S))
        for a, j in enumerate(J):
            place = self.match(j, places)
            mine = place >= 0
            s = self.posteriors[j].values.shape[1]
            out[a, mine, :s] = self.posteriors[j][place[mine]].over(J)
            weight[a, mine, :s] = self.weights[j][place[mine]]
        return Forecast(out, weight, None if classes is None else J)


def in_object_order(training: dict, names) -> list:
    """``training``'s samples as ``(label, name, instance, sample)``: objects in the order of ``names`` (the label is
    the index there), each object's instances in increasing order.

    Examples
    --------
    >>> [(c, name, j) for c, name, j, _ in in_object_order({("b", 1): 0, ("a", 2): 0, ("a", 1): 0}, ("b", "a"))]
    [(0, 'b', 1), (1, 'a', 1), (1, 'a', 2)]
    """
    label = {name: c for c, name in enumerate(names)}
    keys = sorted(training, key=lambda k: (label[k[0]], k[1]))
    return [(label[name], name, j, training[name, j]) for name, j in keys]


def fit_knowledge(training: dict, recognizer):
    """Touch knowledge from training instances' place samples.

    Parameters
    ----------
    training : dict (object name, instance index) -> PlaceSample or PackedPlaceSample (or any sample whose
        ``in_memory()`` gives one)
        Training instances only (index >= 1); every session of every place is a training touch.
    recognizer : classify.recognizers.touches.Recognizer
        The single-touch classifier (selection is not applied: every place counts).  The place-aware
        recognizer ("place") gives a :class:`PlaceKnowledge` from the samples' codebooks.

    Returns
    -------
    TouchKnowledge or PlaceKnowledge, classes in the order of the sorted object names
    """
    from classify.recognizers.touches import point_groups
    from tactile.features import describe

    names = tuple(sorted({name for name, _ in training}))
    if len(names) < 2 or any(j < 1 for _, j in training):
        raise ValueError(
            f"touch knowledge needs training instances (index >= 1) of at least two objects, got {sorted(training)}"
        )
    if recognizer.classifier == "place":
        from classify.policies.place_knowledge import fit_place_knowledge

        return fit_place_knowledge(training, recognizer.params or {})
    F, y, inst, vertex, located = [], [], [], [], []
    for c, _, j, sample in in_object_order(training, names):
        sample = sample.in_memory()  # read once: a stored sample reads its file on each use
        imprints = sample.imprints  # read once: a packed sample unpacks on each read
        sessions, P = imprints.shape[:2]
        # Described sample by sample: the descriptors are all that is read from here on.
        F.append(describe(imprints.reshape(-1, *imprints.shape[2:]), recognizer.features))
        y.append(np.full(sessions * P, c))
        inst.append(np.full(sessions * P, j))
        vertex.append(np.tile(sample.places.vertex_ids, sessions))
        located += [signatures(sample.places)] * sessions
    F, y, inst, vertex, located = (np.concatenate(a) for a in (F, y, inst, vertex, located))
    groups = point_groups(y, vertex, inst)
    C = len(names)
    # The held-out instances' models, then the model of all of them: fitted together, handed over one at a time.
    held_in = [np.flatnonzero(inst != i) for i in np.unique(inst)]
    models = recognizer.fit_subsets(F, y, groups, [*held_in, np.arange(len(y))])
    held, calibration = _held_out(models, F, y, inst, C, TouchKnowledge.hypotheses)
    model = next(models)
    from classify.recognizers.shortlist import SparseRows

    place_ids, located_places, posteriors, weights = [], [], [], []
    for c in range(len(names)):
        mine = y == c
        ids, where = np.unique(vertex[mine], return_inverse=True)
        counts = np.bincount(where, minlength=ids.size)
        S = int(counts.max())
        T = held.values.shape[1]
        values, classes = np.full((ids.size, S, T), 1.0 / C), np.tile(np.arange(T), (ids.size, S, 1))
        rest = np.full((ids.size, S), 1.0 / C)
        weight = np.zeros((ids.size, S))
        slot = np.zeros(ids.size, np.int64)
        for row, p in zip(np.flatnonzero(mine), where):
            values[p, slot[p]], classes[p, slot[p]], rest[p, slot[p]] = (
                held.values[row],
                held.classes[row],
                held.rest[row],
            )
            weight[p, slot[p]] = 1.0 / counts[p]
            slot[p] += 1
        post = SparseRows(values, classes, rest, C)
        place_ids.append(ids)
        # A vertex lies at one place of its object: the signature of its first training touch.
        first = np.unique(where, return_index=True)[1]
        located_places.append(located[mine][first])
        posteriors.append(post)
        weights.append(weight)
    return TouchKnowledge(
        names,
        tuple(place_ids),
        tuple(located_places),
        tuple(posteriors),
        tuple(weights),
        model,
        calibration,
        recognizer.features,
    )


def _held_out(models, F, y, inst, C: int, H: int, block: int = 4096):
    """Each training touch's calibrated posterior from a classifier fitted without its instance (the next of
    ``models``, an iterator of one per instance in increasing order), as
    :class:`~classify.recognizers.shortlist.SparseRows` (N,): every object up to ``H``, past it each row's
    ``H`` most probable and one value for the others; and the calibration, fitted on those posteriors."""
    from classify.recognizers.classifiers import KNN
    from classify.recognizers.fusion import calibrate, calibrate_rows, calibration_rows, fit_calibration
    from classify.recognizers.shortlist import SparseRows, knn_shortlist, nearest_classes, spread
    from classify.recognizers.touches import posteriors

    dense = C <= H
    T = C if dense else H
    # The rows the calibration is fitted on are kept whole: every row up to H objects.
    pick = np.arange(len(y)) if dense else spread(len(y), calibration_rows(C))
    kept = np.zeros((pick.size, C))
    values, classes, rest = np.zeros((len(y), T)), np.tile(np.arange(T), (len(y), 1)), np.zeros(len(y))
    for i in np.unique(inst):
        out = inst == i
        model = next(models)
        mine = np.flatnonzero(out)
        # Past H objects a block of rows at a time, so that memory stays linear in the objects; a kNN instead
        # reads the training rows of each row's candidate objects only, and a few rows of every other, in
        # blocks of its own: one call prepares the objects' rows once.
        screened = not dense and isinstance(model, KNN) and len(model.classes_) > H
        step = mine.size if dense or screened else block
        for a in range(0, mine.size, step):
            rows = mine[a : a + step]
            hit = np.isin(rows, pick)
            if screened:
                kept[np.searchsorted(pick, rows[hit])] = posteriors(model, F[rows[hit]], C)
                values[rows], found = knn_shortlist(model, F[rows], H)
                classes[rows] = model.classes_[found]
            else:
                P = posteriors(model, F[rows], C)
                kept[np.searchsorted(pick, rows[hit])] = P[hit]
                if not dense:
                    classes[rows] = nearest_classes(-P, H)
                    values[rows] = np.take_along_axis(P, classes[rows], axis=1)
            if not dense:
                rest[rows] = np.maximum(1.0 - values[rows].sum(axis=1), 0.0) / (C - H)
    calibration = fit_calibration(kept, y[pick])
    if dense:
        return SparseRows(calibrate(kept, calibration), classes, rest, C), calibration
    values, rest = calibrate_rows(values, rest, C, calibration)
    return SparseRows(values, classes, rest, C), calibration
