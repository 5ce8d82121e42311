"""The place-aware recognizer's knowledge: each object's touch codebooks at its places, and the forecast.

A training instance's codebooks (``tactile.touch_codebook``) become the
banks of ``classify.recognizers.place.PlaceAware`` (:func:`place_touches`,
pooled by :func:`place_keys`); :class:`PlaceKnowledge` locates a test
instance's places on each object (by registration, when first needed) and
forecasts what a touch there would make of the belief.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np

from classify.policies.knowledge import LANDMARKS, Forecast, Places, in_object_order, signatures

__all__ = ["PlaceKnowledge", "fit_place_knowledge", "place_keys", "place_touches"]


def place_keys(signatures: np.ndarray) -> np.ndarray:
    """(k,) int64 keys of points by where they lie: equal signatures (to 1e-7) share a key, so the touches of one
    place of an object, on any of its instances and from any source, pool into one entry."""
    import hashlib

    rounded = np.round(np.asarray(signatures, np.float64), 7) + 0.0  # -0.0 and 0.0 alike
    return np.array(
        [
            int.from_bytes(hashlib.blake2b(row.tobytes(), digest_size=8).digest(), "little", signed=True)
            for row in rounded
        ],
        dtype=np.int64,
    )


def place_touches(samples: dict, names: tuple, points=None, dtype=None) -> tuple:
    """Codebook touches of training instances as the place-aware recognizer takes them.

    Parameters
    ----------
    samples : dict (object name, instance index) -> PlaceSample (or PackedPlaceSample) with a codebook
    names : tuple of str, the classes in order
    points : dict (object name, instance index) -> a fixed plan's training sample, optional
        Its ``positions`` (k, 3) and ``codebook`` (k, draws, d): the plan's
        points, located against the instance's landmarks, instead of the places.
    dtype : numpy dtype of X, optional (default: the codebooks')

    Returns
    -------
    X (N, d), y (N,), signatures (N, LANDMARKS), instances (N,), keys (N,)
    """
    # Two passes: the first locates the touches and counts them, the second copies the codebooks into X, which is
    # allocated once (a thousand objects' codebooks, gathered and then joined, would lie twice in memory).
    found, kinds = [], []
    for c, name, j, sample in in_object_order(samples, names):
        book, where = _codebook(sample, name, j, points, locate=True)
        found.append((c, j, where, book.shape[1]))
        kinds.append(book.dtype)
    d = book.shape[2]
    X = np.empty((sum(len(w) * n for _, _, w, n in found), d), dtype or np.result_type(*kinds))
    start = 0
    for _, name, j, sample in in_object_order(samples, names):
        book = _codebook(sample, name, j, points)[0]
        X[start : start + book.shape[0] * book.shape[1]] = book.reshape(-1, d)
        start += book.shape[0] * book.shape[1]
    # Per place, then repeated per draw: no per-touch array is gathered in pieces.
    where = np.concatenate([w for _, _, w, _ in found])
    places = [len(w) for _, _, w, _ in found]
    draws = np.repeat([n for _, _, _, n in found], places)
    y = np.repeat(np.repeat([c for c, _, _, _ in found], places), draws)
    inst = np.repeat(np.repeat([j for _, j, _, _ in found], places), draws)
    sig, keys = np.repeat(where, draws, axis=0), np.repeat(place_keys(where), draws)
    return X, y, sig, inst, keys


def _codebook(sample, name: str, j: int, points, locate: bool = False) -> tuple:
    """A training instance's codebook (k, draws, d) at its touchable places, or at a fixed plan's points (from
    ``points``), and with ``locate`` where those lie against its landmarks (k, LANDMARKS) (else None)."""
    sample = sample.in_memory()  # read once: a stored sample reads its file on each use
    if sample.codebook is None:
        raise ValueError(f"{name}, training instance {j}: no touch codebook (run with the place-aware recognizer)")
    if points is None:
        ok = sample.places.touchable
        positions, book = sample.places.positions[ok], sample.codebook[ok]
    else:
        plan = points[name, j]
        positions, book = plan.positions, plan.codebook
    return book, signatures(sample.places, positions) if locate else None


def _session_touches(samples: dict, names: tuple) -> tuple:
    """Each training instance's session-0 touches at its touchable places (one device): descriptors, objects,
    signatures, instances."""
    from tactile.features import polar_fourier

    X, y, sig, inst = [], [], [], []
    for c, _, j, sample in in_object_order(samples, names):
        sample = sample.without_codebook().in_memory()  # read once, and never the codebook it does not use
        ok = sample.places.touchable
        X.append(polar_fourier(sample.imprints[0][ok]))
        y.append(np.full(ok.sum(), c))
        sig.append(signatures(sample.places)[ok])
        inst.append(np.full(ok.sum(), j))
    return tuple(np.concatenate(a) for a in (X, y, sig, inst))


@dataclass(frozen=True, eq=False)
class PlaceKnowledge:
    """The place-aware recognizer's knowledge: each object's touch codebooks at its places, and the forecast.

    A touch at a place of the test instance is scored, under each object,
    against the codebook touches of the places with the nearest signatures
    (``classify.recognizers.place.PlaceAware``); the belief multiplies those
    tempered likelihoods.  Under the hypothesis "the object is j" the test
    instance's places are first laid onto j's training places
    (``meshsal.points.places.landmarks_in``), so that they are located
    against j's own landmarks even when the instance's tessellation put its
    landmarks elsewhere; every hypothesis is treated alike, and how well the
    places fit is never evidence.  Past the recognizer's shortlist, a touch is
    located so only under the ``exact_places`` objects its screening puts
    nearest, and a forecast under none: elsewhere j's landmarks are laid onto
    the instance through the two surface frames
    (``meshsal.points.frames.lay_landmarks``: each instance's own, from its
    surface alone), so that the registrations per test instance stay bounded
    however many objects there are, and another tessellation of the test
    instance still finds j's places.  The forecast of a place under j is what
    j's codebook touches at its matched places would make of the belief.

    Attributes
    ----------
    names : tuple of str
    model : classify.recognizers.place.PlaceAware, fitted on the training instances' codebooks
    table : list of classify.recognizers.shortlist.SparseRows (E_j, S), ``model.forecast_table()`` posteriors
    table_weights : list of (E_j, S) float64
    references : tuple of (P_j, 3) float64, each object's training places (its first training instance's)
    frames : tuple of meshsal.points.frames.ShapeFrame, the surface frame of that instance
    features : str, always "polar"
    """

    names: tuple
    model: object
    table: list
    table_weights: list
    references: tuple
    frames: tuple
    features: str = "polar"
    #: Matched entries a forecast draws on per object and place.
    forecast_neighbours: int = 2
    _landmarks: dict = field(default_factory=dict, repr=False)
    _references: dict = field(default_factory=dict, repr=False)

    @property
    def n_classes(self) -> int:
        return len(self.names)

    #: A touch is scored where it was taken, on its own instance's places: never in a batch of instances.
    place_free = False

    @property
    def hypotheses(self) -> int:
        """Hypotheses a forecast holds at most: the recognizer's shortlist."""
        return int(self.model.shortlist)

    def landmarks(self, places: Places, c: int) -> np.ndarray:
        """(LANDMARKS, 3) object ``c``'s landmarks laid onto the instance of ``places`` (computed once per
        instance and object, when first asked for)."""
        from meshsal.points.places import landmarks_in, registration_places

        key = id(places)
        found = self._landmarks.get(key)
        if found is None or found[0] is not places:
            if len(self._landmarks) > 4096:
                self._landmarks.clear()
            found = (places, {}, registration_places(places.positions))
            self._landmarks[key] = found
        if c not in found[1]:
            found[1][c] = landmarks_in(found[2], self._reference(c))
        return found[1][c]

    def _reference(self, c: int):
        """Object ``c``'s training places prepared for registration (once per object)."""
        from meshsal.points.places import registration_places

        if c not in self._references:
            self._references[c] = registration_places(self.references[c])
        return self._references[c]

    def laid_landmarks(self, places: Places, classes=None) -> np.ndarray:
        """(J, LANDMARKS, 3) the landmarks of each object of ``classes`` (default: every object) laid onto the
        instance of ``places`` through the two surface frames (``meshsal.points.frames.lay_landmarks``)."""
        if places.frame is None:
            raise ValueError(
                "the instance's places have no surface frame (meshsal.points.frames.shape_frame): past the "
                "recognizer's shortlist its places are located through it"
            )
        coords = self._landmarks_in_frames
        if classes is not None:
            coords = coords[np.asarray(classes, np.int64)]
        return places.frame.from_shape(coords.reshape(-1, 3)).reshape(coords.shape)

    @functools.cached_property
    def _landmarks_in_frames(self) -> np.ndarray:
        """(C, LANDMARKS, 3) each object's landmarks in its own surface frame."""
        return np.stack([f.to_shape(r[:LANDMARKS]) for f, r in zip(self.frames, self.references)])

    def signatures_at(self, positions, places: Places, classes=None, registered=None) -> np.ndarray:
        """(k, J, LANDMARKS) where points of the instance of ``places`` lie on each object of ``classes``
        (default: every object).

        ``registered`` (k,) bool, optional: the points located by registering
        the instance onto each object (default: every point); the others are
        located against each object's landmarks laid onto the instance through
        the two surface frames (:meth:`laid_landmarks`).
        """
        from meshsal.points.places import signatures as located

        positions = np.asarray(positions, np.float64).reshape(-1, 3)
        J = np.arange(self.n_classes) if classes is None else np.asarray(classes, np.int64)
        mask = None if registered is None else np.asarray(registered, bool)[:, None]
        laid = None if mask is None or mask.all() else located(positions, self.laid_landmarks(places, J))
        if laid is not None and not mask.any():
            return laid  # registered onto nothing

        def under(a: int, j: int) -> np.ndarray:
            at = located(positions, self.landmarks(places, j))
            return at if laid is None else np.where(mask, at, laid[:, a])

        return np.stack([under(a, int(j)) for a, j in enumerate(J)], axis=1)

    def posterior(self, imprints: np.ndarray, places: Places) -> np.ndarray:
        """(k, C) single-touch posteriors of imprints (k, rows, cols) taken at the first k of ``places``."""
        return self.posterior_at(imprints, places.positions[: len(imprints)], places)

    def posterior_at(self, imprints: np.ndarray, positions, places: Places) -> np.ndarray:
        """(k, C) single-touch posteriors of imprints taken at ``positions`` (k, 3) on the instance of ``places``."""
        if len(imprints) == 0:
            return np.zeros((0, self.n_classes))
        positions = np.asarray(positions, np.float64)

        # Located on an object only when the model asks: when the object is on a touch's shortlist; past the
        # shortlist, by registration only under the objects the screening puts nearest (``exact``), and through
        # the surface frames under every object at once (c None).
        def where(c, rows, exact):
            if c is None:
                return self.signatures_at(positions[rows], places, None, np.zeros(len(rows), bool))
            return self.signatures_at(positions[rows], places, [c], exact)[:, 0]

        return self.model.predict_proba(imprints, where)

    def forecast(self, places: Places, classes=None) -> Forecast:
        """The :class:`Forecast` of an instance's candidate places under ``classes`` (default: every object),
        from the codebooks of the matched entries."""
        C, P = self.n_classes, len(places)
        J = np.arange(C) if classes is None else np.asarray(classes, np.int64)
        # Past the shortlist the places are located through the surface frames under every hypothesis: a
        # forecast only ranks places.  Registering onto its hypotheses (255 objects, 4 exact
        # places) took 78 registrations per test instance instead of 49, and moved the rates by 1.6 points at most.
        G = self.signatures_at(places.positions, places, J, np.zeros(P, bool) if C > self.hypotheses else None)
        K = self.forecast_neighbours
        S = self.table[0].values.shape[1]
        out = np.full((J.size, P, K * S, J.size), 1.0 / J.size)
        weight = np.zeros((J.size, P, K * S))
        for a, j in enumerate(J):
            idx, w = self.model.match(j, G[:, a])
            k = min(K, idx.shape[1])
            idx, w = idx[:, :k], w[:, :k] / w[:, :k].sum(axis=1, keepdims=True)
            for b in range(k):
                out[a, :, b * S : (b + 1) * S] = self.table[j][idx[:, b]].over(J)
                weight[a, :, b * S : (b + 1) * S] = w[:, b, None] * self.table_weights[j][idx[:, b]]
        return Forecast(out, weight, None if classes is None else J)


def fit_place_knowledge(training: dict, params: dict | None = None) -> PlaceKnowledge:
    """:class:`PlaceKnowledge` from training instances' place samples with codebooks (``params`` for the
    ``place`` recognizer, as ``classify.make`` takes them)."""
    from classify.recognizers.classifiers import make

    names = tuple(sorted({name for name, _ in training}))
    X, y, sig, inst, keys = place_touches(training, names, dtype=np.float64)
    model = make("place", **(params or {}).get("place", {}))
    # The banks take X standardized in place (no float64 copy beside it); the touches then go before the
    # held-out session is read and the fit chooses its parameters, whose scoring (under every object, screened
    # by place) would lie beside them.
    model._fit_banks(X, y, sig, inst, keys, overwrite_X=True, first_touches=False)
    del X, y, sig, inst, keys
    model._choose(_session_touches(training, names))
    table, weights = model.forecast_table()
    # Each object's first training instance.
    first = {}
    for _, name, j, _ in in_object_order(training, names):
        first.setdefault(name, j)
    references = tuple(training[name, first[name]].places.positions for name in names)
    frames = tuple(training[name, first[name]].places.frame for name in names)
    return PlaceKnowledge(names, model, table, weights, references, frames)
