"""The place-aware recognizer: what a touch at a known place should feel like under each object.

A robot knows where it pressed.  Under the hypothesis "the object is i",
that place is a known place of i, and a toolkit that holds i's training
meshes can simulate many touches there (``tactile.touch_codebook``).  So the
evidence of a touch is a likelihood, ``p(descriptor | object i, place)``,
not a place-free classifier's posterior.

:class:`PlaceAware` is a scikit-learn style estimator of that likelihood:

* **Banks.**  Each object's training touches are grouped into entries, one
  per trained place (a vertex of its training instances), each located by
  its signature (``meshsal.points.places.signatures``: pose- and size-free).
* **Soft match.**  A touch's place is matched, under hypothesis i, to i's
  ``neighbours`` entries with the nearest signatures, weighted by a Gaussian
  in signature distance of width ``match_width`` times the median spacing of
  i's entries.  The weights sum to one under every hypothesis, so how well a
  place matches is never evidence (that would be recognition by sight), and
  the places of a symmetric shape share their weight.
* **Density.**  A Gaussian kernel density over the entries' roll-invariant
  polar descriptors (``tactile.features.polar_fourier``), standardized,
  then whitened by the pooled spread of the touches of one place about
  their place's mean (what a device, a roll and a placement error change),
  so that the kernel weighs a difference by how much one place varies in
  it: a touch near an edge can slide off it under placement error, so the
  touches of one place need not form one blob, which a kernel density
  follows and a Gaussian per place would not.
* **Place-free term.**  Mixed in with weight ``w``: a kernel density over a
  fixed subsample of all of i's touches, so that a wrong match cannot sink
  the true object.
* **Tempering.**  The log-likelihoods of several touches add, divided by a
  temperature ``T``: the touches of one session share a device (gain map,
  dead taxels), which the product of independent likelihoods would count as
  new evidence at every touch.

The bandwidth, ``w`` and ``T`` are chosen on a grid by leaving each
training instance out in turn: a model of the other instances scores the
held-out instance's session touches (one device for all its places), and the
mean negative log-likelihood of the true object after 1, 2, 3 and 5 of them,
fused, is minimized.  Nothing of a test instance enters the fit.
"""

from __future__ import annotations

import numpy as np
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.utils.validation import check_is_fitted

from classify.recognizers.banks import (
    Bank,
    BankStack,
    entries,
    evenly_spaced,
    free_d2,
    free_subsample,
    lse,
    sample_d2,
    spacing,
    within_place_whitening,
)
from classify.recognizers.shortlist import EXACT_PLACES, SHORTLIST, FreeStack, SparseRows, nearest_classes, spread

__all__ = ["SCREENINGS", "PlaceAware", "describe_touches"]

_NEG = -np.inf
#: Temperatures tried by default: 0.25 to 64, evenly on a log scale.
_TEMPERATURES = tuple(float(t) for t in np.round(np.geomspace(0.25, 64.0, 17), 4))
#: Tempered log-likelihoods held at once while fitting the temperature (512 KB: a core's cache).
_TEMPERED = 1 << 16
#: Rows whitened at a time in the fit (5.5 MB of 42 descriptors).
_ROWS = 1 << 14
#: Touches scored at a time under each object by ``PlaceAware._log_terms``.
_CHUNK = 1 << 10
#: Bytes of each (held-out touches, objects) array the fit's choice of parameters holds at once.
_HELD_OUT = 1 << 25
#: Bytes of each (touches, objects) array the forecast table holds at once (it holds several).
_FORECAST = 1 << 23
#: Bytes of matched samples gathered at once when every object scores a touch (``BankStack``).
_STACKED = 1 << 26
#: How a touch is scored past the shortlist (``PlaceAware(screening=...)``).
SCREENINGS = ("place", "touch")


def describe_touches(X, copy: bool = True) -> np.ndarray:
    """Polar descriptors of imprints (N, rows, cols), or descriptors (N, d) as they are: (N, d) float64.

    With ``copy=False``, float64 descriptors come back as the same array.
    """
    X = np.asarray(X)
    if X.ndim == 3:
        from tactile.features import polar_fourier

        return polar_fourier(X)
    if X.ndim != 2:
        raise ValueError(f"touches must be imprints (N, rows, cols) or descriptors (N, d), got shape {X.shape}")
    return X.astype(np.float64, copy=copy)


def _tempered_losses(total: np.ndarray, truth: np.ndarray, temps: np.ndarray) -> np.ndarray:
    """(temps, m) negative log posterior of the true objects, summed log-likelihoods ``total`` (m, C) tempered by
    each of ``temps``: ``lse(total / T) - total[truth] / T``.  A row's losses do not depend on the other rows.

    One temperature and a few rows at a time, in one buffer that stays in the
    cache (each pass over a large one waits on memory more than it computes);
    the operations are ``lse``'s, so the values are its, bit for bit.  Each
    row's maximum is taken once: dividing by a positive temperature keeps the
    order, and rounding never reverses it, so the maximum of the tempered row
    is the tempered maximum, exactly.
    """
    m, C = total.shape
    step = max(1, min(m, _TEMPERED // max(C, 1)))
    buffer = np.empty((step, C))
    rows = np.arange(step)
    peak = total.max(axis=1)
    losses = np.empty((temps.size, m))
    for j, T in enumerate(temps):
        tops = peak / T
        tops = np.where(np.isfinite(tops), tops, 0.0)[:, None]
        for a in range(0, m, step):
            b = min(a + step, m)
            scaled, top = buffer[: b - a], tops[a:b]
            np.divide(total[a:b], T, out=scaled)
            picked = scaled[rows[: b - a], truth[a:b]]
            np.exp(np.subtract(scaled, top, out=scaled), out=scaled)
            with np.errstate(divide="ignore"):
                losses[j, a:b] = (np.log(scaled.sum(axis=1, keepdims=True)) + top)[:, 0] - picked
    return losses


def _kernel_terms(logw, d2, fd2, inv) -> tuple[np.ndarray, np.ndarray]:
    """Place and place-free log terms, each (len(inv), ...), from the log match weights (..., K) of a touch's
    matched entries, the squared distances (..., K, S) to their samples and (..., F) to the place-free samples
    (inf where left out); ``inv`` is 1 / (2 width^2) per width."""
    # Log-means of kernels over each entry's samples: the nearest sample sets the scale of the sum.
    near, fnear = d2.min(axis=-1, keepdims=True), fd2.min(axis=-1, keepdims=True)
    count, fcount = np.isfinite(d2).sum(axis=-1), np.isfinite(fd2).sum(axis=-1)
    valid = count > 0
    logw = np.where(valid, logw, _NEG)
    top = logw.max(axis=-1, keepdims=True)
    place, free = np.empty((len(inv), *logw.shape[:-1])), np.empty((len(inv), *logw.shape[:-1]))
    with np.errstate(divide="ignore", invalid="ignore"):
        norm = np.log(np.exp(logw - top).sum(axis=-1)) + top[..., 0]
        rel, frel = np.where(valid[..., None], d2 - near, np.inf), fd2 - fnear
        logcount, flogcount = np.log(np.maximum(count, 1)), np.log(np.maximum(fcount, 1))
        for b, s in enumerate(inv):
            lm = np.log(np.exp(-s * rel).sum(axis=-1)) - s * near[..., 0] - logcount
            lm = np.where(valid, lm + logw, _NEG)
            peak = lm.max(axis=-1, keepdims=True)
            place[b] = np.log(np.exp(lm - peak).sum(axis=-1)) + peak[..., 0] - norm
            free[b] = np.log(np.exp(-s * frel).sum(axis=-1)) - s * fnear[..., 0] - flogcount
    # A touch whose every matched entry is left out leans on the place-free term alone.
    place[np.isnan(place)] = _NEG
    return place, free


class PlaceAware(ClassifierMixin, BaseEstimator):
    """Place-aware likelihood of touches: a kernel density per object and place, matched by signature.

    Parameters
    ----------
    bandwidths : tuple of float
        Kernel widths tried, in units of the median distance between a
        held-out touch and its place's training touches.
    mixtures : tuple of float
        Weights of the place-free term tried, in (0, 1).
    temperatures : tuple of float
        Temperatures tried (the log-likelihoods of the touches are summed, then divided by it).
    neighbours : int
        Entries a place is matched to under each hypothesis.
    match_width : float
        Width of the soft match, as a fraction of the median signature
        distance between an object's neighbouring entries (it is not fitted:
        a held-out training instance's places match the others' exactly).
    free_samples : int
        Touches per object in the place-free term (an even subsample).
    fit_touches : tuple of int
        Touch counts whose fused log-loss the fit minimizes.
    fit_sets : int
        Random touch sets per held-out instance and touch count.
    fit_places : int
        Held-out touches per instance the fit scores (spread over its places).
    whiten : bool
        Whiten the descriptors by the pooled within-place covariance (shrunk
        a tenth towards its diagonal) instead of standardizing them only.
    shortlist : int
        Objects a touch is scored under in full: those whose place-free
        samples come nearest it (``classify.recognizers.shortlist``); every
        other object keeps a lower bound of its likelihood.  With no more
        objects than this, every object is scored in full.
    exact_places : int or None
        Past the shortlist, the objects under which a touch's place is asked
        for in full (by registration, in ``PlaceKnowledge``) when
        ``signatures`` is a function; under the others it is located more
        cheaply, each object's landmarks laid onto the touched instance
        through the two surface frames (``meshsal.points.frames``).  Screened by touch,
        the shortlisted objects nearest by the screening (None: 8,
        ``EXACT_PLACES``); screened by place, the objects most likely at the
        cheap place, which are then scored again (None: 0, none).
    screening : {"place", "touch"}
        How a touch is scored past the shortlist (more objects than
        ``shortlist``).  ``"place"`` (the default): every object is
        scored in full, the touch's place located through the surface frames,
        in one pass over the banks stacked (``BankStack``,
        whose arrays the banks then read: the samples held once); it keeps
        the true object where a touch alone would drop it, and the fit scores
        its held-out touches under every object (the forecast tables stay
        shortlisted by the touch alone).  ``"touch"``: by the touch alone; the
        ``shortlist`` objects whose place-free samples come nearest are scored
        in full, every other object by a lower bound; at 999 objects it is
        no faster, and right after five touches in 26 % of cases where
        ``"place"`` is in 98 % (``docs/benchmarks/bench_scaling_touch.md``,
        ``bench_scaling_place.md``).
        Registering the most likely objects again (``exact_places``) lets
        the test instance's shape in: the true object, when among those
        scored again, tends to win even when what was felt came from another
        object (at 255 objects, 8 registered, the controls sit near 8 / 255,
        not at chance: ``docs/benchmarks/bench_screening.md``).
    fit_objects : int
        Objects whose held-out instances score the fit's grid (evenly spread
        over the objects when there are more).
    random_state : int
        Seeds the touch sets of the fit.

    Attributes
    ----------
    classes_ : (C,) int64
    bandwidth_, mixture_, temperature_ : float
        The fitted parameters (``bandwidth_`` in standardized descriptor units).
    fit_loss_ : float
        The fitted parameters' mean held-out log-loss.

    Examples
    --------
    Two objects, one place each, telling them apart by what is felt there:

    >>> rng = np.random.default_rng(0)
    >>> X = np.r_[rng.normal(0, 1, (40, 3)), rng.normal(4, 1, (40, 3))]
    >>> y, inst = np.repeat([0, 1], 40), np.tile(np.repeat([1, 2], 20), 2)
    >>> sig, key = np.zeros((80, 2)), np.zeros(80, int)
    >>> model = PlaceAware().fit(X, y, signatures=sig, instances=inst, places=key)
    >>> model.predict(np.array([[0.2, 0.0, -0.1], [3.9, 4.2, 4.0]]), np.zeros((2, 2))).tolist()
    [0, 1]
    """

    def __init__(
        self,
        bandwidths=(0.25, 0.35, 0.5, 0.7, 1.0, 1.4, 2.0, 2.8, 4.0),
        mixtures=(0.003, 0.01, 0.03, 0.1, 0.3),
        temperatures=_TEMPERATURES,
        neighbours=4,
        match_width=0.25,
        free_samples=64,
        fit_touches=(1, 2, 3, 5),
        fit_sets=50,
        fit_places=100,
        whiten=True,
        shortlist=SHORTLIST,
        exact_places=None,
        screening="place",
        fit_objects=64,
        random_state=0,
    ):
        self.bandwidths = bandwidths
        self.mixtures = mixtures
        self.temperatures = temperatures
        self.neighbours = neighbours
        self.match_width = match_width
        self.free_samples = free_samples
        self.fit_touches = fit_touches
        self.fit_sets = fit_sets
        self.fit_places = fit_places
        self.whiten = whiten
        self.shortlist = shortlist
        self.exact_places = exact_places
        self.screening = screening
        self.fit_objects = fit_objects
        self.random_state = random_state

    # -- fitting ---------------------------------------------------------------------------------

    def fit(self, X, y, *, signatures, instances, places, session=None, overwrite_X=False):
        """Build the banks and choose the bandwidth, mixture and temperature by leaving instances out.

        Parameters
        ----------
        X : (N, rows, cols) imprints or (N, d) descriptors
            Training touches (a codebook: many per place and instance).
        y : (N,) int, their objects
        signatures : (N, L) float64, where each touch's place lies on its instance
        instances : (N,) int, the training instance of each touch (at least two distinct)
        places : (N,) int, the place key (e.g. vertex id): the touches of one object with one key are one entry
        session : tuple (X, y, signatures, instances), optional
            Touches of one acquisition session per training instance (one
            device at all its places): what the held-out instance feels in the
            fit.  Default: the first codebook touch of each of its places.
        overwrite_X : bool
            Float64 descriptors ``X`` may be standardized and whitened in place
            (``X`` is then overwritten): a thousand objects' codebooks are
            millions of touches, and a float64 copy beside them is hundreds of
            megabytes.

        Returns
        -------
        self
        """
        first = self._fit_banks(X, y, signatures, instances, places, overwrite_X, first_touches=session is None)
        self._choose(first if session is None else session)
        return self

    def _fit_banks(self, X, y, signatures, instances, places, overwrite_X, first_touches=True):
        """The first half of :meth:`fit`: check the parameters and touches, standardize and whiten, build the banks.

        Returns, with ``first_touches``, the default held-out session the
        second half (``_choose``) scores: the first touch of each place and
        instance (else None).  A caller with its own session, whose ``X`` is
        spent, lets it go in between (``fit_place_knowledge``): the choice,
        screened by place, scores under every object.
        """
        Z = describe_touches(X, copy=not overwrite_X)
        y = np.asarray(y, np.int64)
        sig = np.asarray(signatures, np.float64)
        inst = np.asarray(instances, np.int64)
        keys = np.asarray(places, np.int64)
        n = len(y)
        if not (len(Z) == n == len(sig) == len(inst) == len(keys)):
            raise ValueError(
                f"X, y, signatures, instances and places must have one row per touch, got "
                f"{len(Z)}, {n}, {len(sig)}, {len(inst)}, {len(keys)}"
            )
        self.classes_ = np.unique(y)
        if self.classes_.size < 2:
            raise ValueError(f"the place-aware recognizer needs touches of at least two objects, got {self.classes_}")
        if np.unique(inst).size < 2:
            raise ValueError("the place-aware recognizer needs at least two training instances (it leaves one out)")
        if not (0 < min(self.mixtures) and max(self.mixtures) < 1):
            raise ValueError(f"mixtures must lie in (0, 1), got {self.mixtures}")
        if not min(self.temperatures) > 0:
            raise ValueError(f"temperatures must be positive, got {self.temperatures}")
        if min(self.shortlist, self.fit_objects) < 1 or int(self.shortlist) != self.shortlist:
            raise ValueError(
                f"shortlist and fit_objects must be positive integers, got {self.shortlist}, {self.fit_objects}"
            )
        if self.exact_places is not None and not (0 <= self.exact_places == int(self.exact_places)):
            raise ValueError(f"exact_places must be a non-negative integer or None, got {self.exact_places}")
        if self.screening not in SCREENINGS:
            raise ValueError(f"screening must be one of {SCREENINGS}, got {self.screening!r}")
        self.mean_ = Z.mean(axis=0)
        self.scale_ = np.maximum(Z.std(axis=0), 1e-9 * max(float(Z.std()), 1e-300))
        session = None
        if first_touches:
            first = np.unique(np.c_[y, inst, keys], axis=0, return_index=True)[1]
            session = (Z[first], y[first], sig[first], inst[first])
        # Standardized and whitened in place, a block of rows at a time: the operations of _standardized with one
        # touch-sized array beside the banks, not two (a thousand objects' codebooks are millions of touches).
        # A row's product does not depend on the other rows as long as the blocks stay large: the last one takes
        # the remainder (BLAS computes a single row, or a few, another way).
        Z -= self.mean_
        Z /= self.scale_
        self.whitening_ = within_place_whitening(Z, y, keys) if self.whiten else np.eye(Z.shape[1])
        starts = range(0, max(n - _ROWS, 1), _ROWS)
        for a, b in zip(starts, [*starts[1:], n]):
            Z[a:b] = Z[a:b] @ self.whitening_
        self.banks_ = []
        for c in self.classes_:
            mine = y == c
            k, s, samples, sample_inst = entries(keys[mine], Z[mine], sig[mine], inst[mine])
            free = free_subsample(keys[mine], inst[mine], self.free_samples)
            self.banks_.append(
                Bank(k, s, samples, sample_inst, Z[mine][free], inst[mine][free], self.match_width * spacing(s))
            )
        self.free_ = FreeStack.of([b.free for b in self.banks_], [b.free_instances for b in self.banks_])
        return session

    def _standardized(self, D: np.ndarray) -> np.ndarray:
        return ((D - self.mean_) / self.scale_) @ self.whitening_

    def _choose(self, session):
        Xs, ys, sigs, insts = session
        Zs = self._standardized(describe_touches(Xs))
        ys = np.searchsorted(self.classes_, np.asarray(ys, np.int64))
        sigs, insts = np.asarray(sigs, np.float64), np.asarray(insts, np.int64)
        # At most fit_places touches of each held-out instance, spread over its places, score the grid.
        C = len(self.banks_)
        scored = spread(C, self.fit_objects)
        # An instance is held out only if its object keeps touches of another one (else nothing scores it).
        trained = [set(np.unique(bank.instances[bank.instances >= 0]).tolist()) for bank in self.banks_]
        keep = []
        for c, t in sorted(set(zip(ys.tolist(), insts.tolist()))):
            if c not in scored or not trained[c] - {t}:
                continue
            rows = np.flatnonzero((ys == c) & (insts == t))
            keep.append(rows[evenly_spaced(rows.size, self.fit_places)])
        if not keep:
            raise ValueError(
                "the place-aware recognizer needs an object with touches on two training instances (it leaves one "
                "out and scores it with the others), got one instance per object"
            )
        keep = np.concatenate(keep)  # an instance's rows together: the choice scores them in blocks of rows
        Zs, ys, sigs, insts = Zs[keep], ys[keep], sigs[keep], insts[keep]
        # The width unit: how far a held-out touch lies from its own place's training touches.
        near = []
        for c, bank in enumerate(self.banks_):
            rows = np.flatnonzero(ys == c)
            if rows.size == 0:
                continue
            idx, _ = self._match(bank, sigs[rows])
            d2 = sample_d2(bank, Zs[rows], idx[:, :1], insts[rows])
            near.append(np.sqrt(d2[np.isfinite(d2)]))
        near = np.concatenate(near)
        unit = float(np.median(near)) if near.size else 1.0
        widths = unit * np.asarray(self.bandwidths, np.float64)
        rng = np.random.default_rng(self.random_state)
        groups = [np.flatnonzero((ys == c) & (insts == t)) for c, t in sorted(set(zip(ys.tolist(), insts.tolist())))]
        sets = [
            (k, rows[np.argsort(rng.random((self.fit_sets, rows.size)), axis=1)[:, :k]], ys[rows[0]])
            for k in self.fit_touches
            for rows in groups
            if rows.size >= k
        ]
        temps = np.asarray(self.temperatures, np.float64)
        counts = [k for k in self.fit_touches if any(kk == k for kk, _, _ in sets)]
        chosen = {k: [(rows, truth) for kk, rows, truth in sets if kk == k] for k in counts}
        # An instance's rows are contiguous: its first and its last row, for each row.
        first, until = np.empty(len(Zs), np.int64), np.empty(len(Zs), np.int64)
        for rows in groups:
            first[rows], until[rows] = rows[0], rows[-1]
        ends = {k: np.array([until[rows[0, 0]] for rows, _ in chosen[k]]) for k in counts}
        # (temps, sets) summed tempered losses of each set's fit_sets draws, for each width, mixture and touch
        # count: the loss is their mean, the same whatever the blocks.
        sums = {
            (a, m, k): np.empty((temps.size, len(chosen[k])))
            for a in range(len(widths))
            for m in range(len(self.mixtures))
            for k in counts
        }
        # The held-out touches are scored a block of rows at a time, so that the (rows, C) arrays stay a few tens of
        # megabytes at a thousand objects.  A block is whole chunks of _log_terms, so each row is scored beside the
        # same rows as in one call; the log-likelihoods of an instance that goes on in the next block wait for it
        # (rows lo to A, one array per width and mixture).  Screened by place, every width is scored in one call,
        # which finds each row's matched samples and distances once, in blocks of at most _CHUNK rows whose
        # (widths, rows, C) arrays stay near _HELD_OUT bytes; screened by touch, one width at a time, each reading
        # the same screening.
        N = len(Zs)
        by_place = C > self.shortlist and self.screening == "place"
        if by_place:
            block = min(_CHUNK, max(64, _HELD_OUT // (8 * C * len(widths))))
        else:
            block = _CHUNK * max(1, _HELD_OUT // (_CHUNK * 8 * C))
        lo, held = 0, {}
        for A in range(0, N, block):
            B = min(A + block, N)
            span = slice(A, B)
            if C <= self.shortlist or by_place:
                every = self._log_terms(Zs[span], sigs[span], insts[span], widths, chunk=_CHUNK)
            else:
                every = None
                screen = self.free_.nearest(Zs[span], insts[span])
            done = {k: np.flatnonzero((ends[k] >= A) & (ends[k] < B)) for k in counts}
            next_lo = first[B - 1] if until[B - 1] >= B else B
            for a, h in enumerate(widths):
                if every is not None:
                    place, free = every[0][a], every[1][a]
                else:
                    place = free = None  # the last width's terms go before this one's are computed
                    place, free, _ = self._log_terms(
                        Zs[span], sigs[span], insts[span], [h], chunk=_CHUNK, screen=screen
                    )
                place, free = place.reshape(B - A, C), free.reshape(B - A, C)
                for m, w in enumerate(self.mixtures):
                    ll = np.empty((B - lo, C))  # rows lo to B
                    if A > lo:
                        ll[: A - lo] = held[a, m]
                    for r in range(A, B, _CHUNK):  # logaddexp(log(1 - w) + place, log(w) + free)
                        out, rows = ll[r - lo : r - lo + _CHUNK], slice(r - A, r - A + _CHUNK)
                        np.logaddexp(np.add(np.log1p(-w), place[rows], out=out), np.log(w) + free[rows], out=out)
                    for k in counts:
                        if done[k].size == 0:
                            continue
                        total = np.empty((done[k].size * self.fit_sets, C))  # each draw's summed rows
                        for n, j in enumerate(done[k]):
                            rows = chosen[k][j][0] - lo
                            np.sum(ll[rows], axis=1, out=total[n * self.fit_sets : (n + 1) * self.fit_sets])
                        truth = np.repeat([chosen[k][j][1] for j in done[k]], self.fit_sets)
                        each = _tempered_losses(total, truth, temps).reshape(temps.size, done[k].size, self.fit_sets)
                        sums[a, m, k][:, done[k]] = each.sum(axis=2)
                    held[a, m] = ll[next_lo - lo :].copy()  # a view would keep the whole block
            lo = next_lo
        best = (np.inf, None)
        for a, h in enumerate(widths):
            for m, w in enumerate(self.mixtures):
                loss = np.zeros(temps.size)
                for k in counts:
                    loss += sums[a, m, k].sum(axis=1) / (self.fit_sets * len(chosen[k])) / len(self.fit_touches)
                t = int(np.argmin(loss))
                if loss[t] < best[0] - 1e-12:
                    best = (float(loss[t]), (float(h), float(w), float(temps[t])))
        self.fit_loss_ = best[0]
        self.bandwidth_, self.mixture_, self.temperature_ = best[1]

    # -- the likelihood --------------------------------------------------------------------------

    def _match(self, bank: Bank, G: np.ndarray):
        """(n, K) entry indices and log weights (summing to one) of each place under one hypothesis."""
        K = min(self.neighbours, len(bank.keys))
        dist, idx = bank.tree.query(G, k=K)
        dist, idx = dist.reshape(len(G), K), idx.reshape(len(G), K)
        logw = -0.5 * (dist**2 - dist[:, :1] ** 2) / bank.match_width**2
        return idx, logw - lse(logw, axis=1, keepdims=True)

    def _log_terms(self, Z, G, exclude, widths, chunk: int = 1024, screen=None, shortlisted=None):
        """Place and place-free log-likelihood terms, each (len(widths), n, C), of touches Z at places G.

        ``G`` is (n, L), the same place under every object, (n, C, L), or a
        function ``G(c, rows, exact)`` giving rows' places under object c as
        (len(rows), L); ``exact`` is (len(rows),) bool, whether c is among the
        row's ``exact_places`` nearest objects by the screening, or None when
        every object is scored with its place located in full.  Past the
        shortlist without one, the function is asked once for the rows, with
        c and ``exact`` None: their places located cheaply, (len(rows), L)
        the same under every object or (len(rows), C, L) each object's (its
        landmarks laid onto the touched instance through the surface frames),
        which are then scored all at once (``BankStack``).  Past the shortlist, when ``shortlisted``
        (default: ``screening == "touch"``), an object off a touch's shortlist has no place term
        (-inf) and the place-free term's nearest kernel alone: lower bounds.
        The third value is the (n, C) bool shortlist then, else None.
        ``screen`` is ``self.free_.nearest(Z, exclude)`` when already at hand.
        """
        n, C = len(Z), len(self.banks_)
        place = np.full((len(widths), n, C), _NEG)
        free = np.full((len(widths), n, C), _NEG)
        inv = 0.5 / np.asarray(widths, np.float64) ** 2
        member = None
        past = C > self.shortlist
        if shortlisted is None:
            shortlisted = self.screening == "touch"
        if past and shortlisted:
            screened, count = self.free_.nearest(Z, exclude) if screen is None else screen
            member = np.zeros((n, C), bool)
            # An object is among a row's exact_places nearest when fewer objects lie strictly nearer: when it lies
            # no farther than the row's exact_places-th least distance, which is a shortlisted one's.
            limit, E = np.full(n, -np.inf), min(self._exact_places(), self.shortlist)
            # A chunk of rows at a time, in place: (n, C) arrays are large at a thousand objects.
            for a in range(0, n, chunk):
                rows = slice(a, a + chunk)
                listed = nearest_classes(screened[rows], self.shortlist)
                np.put_along_axis(member[rows], listed, True, 1)
                if E > 0:
                    near = np.take_along_axis(screened[rows], listed, axis=1)
                    limit[rows] = np.partition(near, E - 1, axis=1)[:, E - 1]
                logcount = np.log(np.maximum(count[rows], 1))
                with np.errstate(invalid="ignore"):
                    for b, s in enumerate(inv):
                        # -s * screened - log(max(count, 1)), -inf where no sample counts
                        term = free[b, rows]
                        np.subtract(np.multiply(-s, screened[rows], out=term), logcount, out=term)
                        term[count[rows] <= 0] = _NEG
        if past and not shortlisted and (callable(G) or G.ndim == 2):
            # Every object at once, at the place located cheaply (the same under every object, or each object's).
            stack = self._stack()
            step = max(1, _STACKED // (C * stack.samples[0].nbytes * min(self.neighbours, stack.signatures.shape[1])))
            for a in range(0, n, step):
                rows = np.arange(a, min(a + step, n))
                g = G(None, rows, None) if callable(G) else G[rows]
                place[:, rows], free[:, rows] = self._every_object_terms(stack, Z[rows], g, exclude[rows], inv)
            return place, free, None
        for a in range(0, n, chunk):
            span = np.arange(a, min(a + chunk, n))
            for c in range(C) if member is None else np.flatnonzero(member[span].any(axis=0)):
                bank = self.banks_[c]
                rows = span if member is None else span[member[span, c]]
                z, ex = Z[rows], exclude[rows]
                if callable(G):
                    g = G(c, rows, None if member is None else screened[rows, c] <= limit[rows])
                else:
                    g = G[rows] if G.ndim == 2 else G[rows, c]
                place[:, rows, c], free[:, rows, c] = self._object_terms(bank, z, g, ex, inv)
        return place, free, member

    def _exact_places(self) -> int:
        """``exact_places``, None read as the screening's default: 8 by touch, 0 by place."""
        if self.exact_places is None:
            return EXACT_PLACES if self.screening == "touch" else 0
        return int(self.exact_places)

    def _stack(self) -> BankStack:
        """The banks stacked for scoring every object at once (built when first asked for, and again when the
        banks change: ``with_places`` gives a copy other banks); the banks then read their samples from it."""
        found = getattr(self, "_stacked", None)
        if found is None or found[0] is not self.banks_:
            found = self._stacked = (self.banks_, BankStack(self.banks_, lend=True))
        return found[1]

    def _object_terms(self, bank: Bank, z, g, ex, inv):
        """Place and place-free log terms, each (len(inv), m), of touches z (m, d) at places g (m, L) under one
        object's ``bank``, each touch leaving out the instance in ``ex`` (m,); ``inv`` is 1 / (2 width^2) per width."""
        idx, logw = self._match(bank, g)
        return _kernel_terms(logw, sample_d2(bank, z, idx, ex), free_d2(bank, z, ex), inv)

    def _every_object_terms(self, stack: BankStack, z, g, ex, inv):
        """Place and place-free log terms, each (len(inv), m, C), of touches z (m, d) at places g (m, L), the same
        under every object, each touch leaving out the instance in ``ex`` (m,): ``_object_terms`` under all of
        ``stack``'s objects at once (one pass over arrays, not a call per object)."""
        idx, logw = stack.match(g, self.neighbours)
        return _kernel_terms(logw, sample_d2(stack, z, idx, ex), free_d2(stack, z, ex), inv)

    def log_likelihood(self, X, signatures, exclude=None) -> np.ndarray:
        """Untempered log-likelihood of each touch under each object, (n, C) float64 (up to one constant).

        Parameters
        ----------
        X : (n, rows, cols) imprints or (n, d) descriptors
        signatures : (n, L) where each touch's place lies on the touched instance, (n, C, L) where it lies
            under each object's hypothesis, or a function ``(c, rows, exact) -> (len(rows), L)`` of the same,
            called only for the objects on a touch's shortlist; ``exact`` (len(rows),) bool says which touches
            have c among their ``exact_places`` nearest objects by the screening (None when every object is
            scored): under the others a caller may locate the place more cheaply.  Screened by place past the
            shortlist, it is asked with c and ``exact`` None for the place located cheaply under every object
            ((len(rows), L) the same under all, or (len(rows), C, L)), then with ``exact`` all True under each
            touch's ``exact_places`` most likely objects
        exclude : (n,) int, optional
            A training instance whose touches each query leaves out (-1: none).
        """
        check_is_fitted(self, "banks_")
        Z = self._standardized(describe_touches(X))
        G = signatures
        if not callable(G):
            G = np.asarray(G, np.float64)
            G = G.reshape(len(Z), -1) if G.ndim <= 2 else G
        ex = np.full(len(Z), -1, np.int64) if exclude is None else np.asarray(exclude, np.int64)
        return self._mixed(Z, G, ex)[0]

    def _mixed(self, Z, G, exclude, chunk: int = _CHUNK, shortlisted=None):
        """The fitted mixture of place and place-free terms of standardized touches Z, (n, C), and
        ``_log_terms``' shortlist (n, C) bool or None.

        Past the shortlist without one (``screening="place"``) and with
        places given as a function, each touch's ``exact_places`` most likely
        objects are scored again, the place located in full.
        """
        place, free, member = self._log_terms(Z, G, exclude, [self.bandwidth_], chunk=chunk, shortlisted=shortlisted)
        w = self.mixture_

        def mixed(place, free):
            return np.logaddexp(np.log1p(-w) + place, np.log(w) + free)

        ll = mixed(place[0], free[0])
        C, E = ll.shape[1], min(self._exact_places(), ll.shape[1])
        if member is None and callable(G) and C > self.shortlist and E > 0:
            inv = np.array([0.5 / self.bandwidth_**2])
            # Ties at the E-th value are broken by the object's index, so the choice does not depend on the order
            # of the rows.
            likely = np.sort(np.argsort(-ll, axis=1, kind="stable")[:, :E], axis=1)
            for c in np.unique(likely):
                rows = np.flatnonzero((likely == c).any(axis=1))
                g = G(c, rows, np.ones(rows.size, bool))
                p, f = self._object_terms(self.banks_[c], Z[rows], g, exclude[rows], inv)
                ll[rows, c] = mixed(p[0], f[0])
        return ll, member

    def predict_proba(self, X, signatures) -> np.ndarray:
        """(n, C) single-touch posteriors: each touch's tempered likelihoods, normalized.

        Their product over touches, normalized, is the belief after those touches.
        """
        ll = self.log_likelihood(X, signatures) / self.temperature_
        return np.exp(ll - lse(ll, axis=1, keepdims=True))

    def predict(self, X, signatures) -> np.ndarray:
        """(n,) the most likely object of each single touch."""
        return self.classes_[np.argmax(self.log_likelihood(X, signatures), axis=1)]

    # -- more places and the forecast ------------------------------------------------------------

    def with_places(self, X, y, *, signatures, instances, places):
        """A copy whose banks also hold these touches (e.g. a fixed plan's training points), fitted parameters kept.

        Touches whose place key an object's bank already has join that entry.
        """
        import copy

        check_is_fitted(self, "banks_")
        Z = self._standardized(describe_touches(X))
        y, sig = np.asarray(y, np.int64), np.asarray(signatures, np.float64)
        inst, keys = np.asarray(instances, np.int64), np.asarray(places, np.int64)
        out = copy.copy(self)
        out.banks_ = []
        for c, bank in zip(self.classes_, self.banks_):
            mine = y == c
            if not mine.any():
                out.banks_.append(bank)
                continue
            old = bank.instances >= 0
            old_keys = np.repeat(bank.keys, old.sum(axis=1))
            old_sig = np.repeat(bank.signatures, old.sum(axis=1), axis=0)
            all_keys = np.r_[old_keys, keys[mine]]
            all_sig = np.r_[old_sig, sig[mine]]
            all_Z = np.r_[bank.samples[old], Z[mine]]
            all_inst = np.r_[bank.instances[old], inst[mine]]
            k, s, samples, sample_inst = entries(all_keys, all_Z, all_sig, all_inst)
            out.banks_.append(Bank(k, s, samples, sample_inst, bank.free, bank.free_instances, bank.match_width))
        return out

    def forecast_table(self, samples: int = 8) -> tuple[list, list]:
        """What a touch at each entry of each object would make of the belief: per object, (E, samples) rows.

        For object j's entry e, up to ``samples`` of its training touches
        (spread over its instances), each scored under every object with its
        own instance left out, tempered and normalized: the single-touch
        posterior it would give.  Rows past an entry's touches are uniform
        (their weight, in the second list, is 0).  Each row keeps its
        shortlisted objects (every object, in order, up to ``shortlist``
        objects) and one value for the others.

        Returns
        -------
        posteriors : list of classify.recognizers.shortlist.SparseRows, (E_j, samples, T) each
        weights : list of (E_j, samples) float64, summing to 1 per entry
        """
        check_is_fitted(self, "banks_")
        C = len(self.banks_)
        T = min(C, self.shortlist)
        # Each entry's picks: up to ``samples`` of its touches, spread over its valid samples (the first count[e],
        # sorted by instance).
        picked = []
        for bank in self.banks_:
            E = len(bank.instances)
            count = (bank.instances >= 0).sum(axis=1)
            take = np.zeros((E, samples), np.int64)
            used = np.zeros((E, samples), bool)
            for e in range(E):
                m = min(samples, int(count[e]))
                take[e, :m] = np.unique(np.linspace(0, count[e] - 1, m).round().astype(np.int64))[:m]
                used[e, :m] = True
            rows_e, rows_s = np.nonzero(used)
            picked.append((used, rows_e, rows_s, take[rows_e, rows_s]))
        # Many objects' rows are scored together: under each object, the rows that shortlist it come in one
        # call, not one per object whose rows they are.  A group's (rows, C) arrays stay near _FORECAST bytes.
        most = max(_CHUNK, _FORECAST // (8 * C))
        # The smallest signed integers that index every object: the table holds T of them per row.
        index = np.min_scalar_type(-C)
        sizes = [len(rows_e) for _, rows_e, _, _ in picked]
        posteriors, weights = [], []
        first = 0
        while first < C:
            last, n = first + 1, sizes[first]
            while last < C and n + sizes[last] <= most:
                n += sizes[last]
                last += 1
            group, first = range(first, last), last
            banks = [(self.banks_[g], *picked[g][1:]) for g in group]
            Z = np.concatenate([bank.samples[e, k] for bank, e, _, k in banks])
            G = np.concatenate([bank.signatures[e] for bank, e, _, _ in banks])
            ex = np.concatenate([bank.instances[e, k] for bank, e, _, k in banks])
            # Past the shortlist an object scores only the rows that shortlist it, so a whole group is one chunk;
            # up to it every object scores every row of a chunk.
            ll, member = self._mixed(
                Z, G, ex, chunk=max(len(Z), 1) if C > self.shortlist else _CHUNK, shortlisted=C > self.shortlist
            )
            ll /= self.temperature_
            post = np.exp(ll - lse(ll, axis=1, keepdims=True))
            if member is None:
                values, classes, rest = (
                    post,
                    np.tile(np.arange(T, dtype=index), (len(post), 1)),
                    np.full(len(post), 1.0 / C),
                )
            else:
                classes = np.nonzero(member)[1].reshape(len(post), T).astype(index)
                values = np.take_along_axis(post, classes, axis=1)
                rest = np.maximum(1.0 - values.sum(axis=1), 0.0) / (C - T)
            start = 0
            for g in group:
                used, rows_e, rows_s, _ = picked[g]
                E, stop = len(used), start + len(rows_e)
                # Rows past an entry's touches are uniform, with no weight.
                v = np.full((E, samples, T), 1.0 / C)
                k = np.tile(np.arange(T, dtype=index), (E, samples, 1))
                r = np.full((E, samples), 1.0 / C)
                v[rows_e, rows_s], k[rows_e, rows_s], r[rows_e, rows_s] = (
                    values[start:stop],
                    classes[start:stop],
                    rest[start:stop],
                )
                posteriors.append(SparseRows(v, k, r, C))
                weights.append(np.where(used, 1.0 / np.maximum(used.sum(axis=1, keepdims=True), 1), 0.0))
                start = stop
        return posteriors, weights

    def match(self, c: int, signatures) -> tuple[np.ndarray, np.ndarray]:
        """Object ``c``'s matched entries of places at ``signatures`` (n, L): (n, K) indices and (n, K) weights."""
        check_is_fitted(self, "banks_")
        idx, logw = self._match(self.banks_[c], np.asarray(signatures, np.float64))
        return idx, np.exp(logw)
