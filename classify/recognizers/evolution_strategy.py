"""The SVM dual solved by a (mu + lambda) evolution strategy, as in Mierswa's evolutionary SVM.

The kernel SVM's dual problem

    maximize   W(a) = sum(a) - 1/2 a^T Q a,   Q_ij = y_i y_j k(x_i, x_j)
    subject to 0 <= a_i <= C,   sum(a * y) = 0

is solved here without SMO: candidate coefficient vectors are mutated at
random, repaired into the feasible set, and selected by the fitness W(a)
alone (I. Mierswa, "Evolutionary learning with kernels: a generic solution
for large margin problems", GECCO 2006).

* each parent carries its own step size ``sigma`` (a fraction of C),
  self-adapted log-normally in every offspring (``sigma' = sigma *
  exp(tau * N(0, 1))``);
* a mutation draws ``pairs`` random pairs of coefficients (i, j) and moves
  ``a_i`` by ``sigma' * C * N(0, 1)`` and ``a_j`` by ``-y_i y_j`` times the
  same amount, which keeps ``sum(a * y) = 0`` exactly; the repair clips the
  move so both coefficients stay inside the box [0, C];
* fitness is exact and cheap: every parent keeps the gradient ``1 - Q a``, so
  an offspring's W follows from a few kernel entries instead of a full
  quadratic form, and the whole population of every one-vs-rest problem is
  evaluated in one vectorised step over a single shared kernel matrix
  (:func:`solve_duals` does the same for several training sets, e.g. the
  folds of a cross-validation, each with its own kernel matrix, generator
  and stopping, and gets for each what it gets alone, bit for bit);
* plus-selection keeps the best ``mu`` of parents and offspring, so W never
  decreases; the run stops after ``max_generations`` or when no offspring has
  improved any parent for ``patience`` generations.

The estimator around it is :class:`classify.recognizers.evolutionary_svm.EvolutionarySVM`.
"""

from __future__ import annotations

import dataclasses
import itertools
from dataclasses import dataclass

import numpy as np

__all__ = ["Strategy", "solve_dual", "solve_duals"]


@dataclass(frozen=True)
class Strategy:
    """The (mu+lambda) evolution strategy of :func:`solve_dual`.

    Attributes
    ----------
    mu, lam : int
        Parents and offspring per generation (per problem).
    pairs : int
        Coefficient pairs moved by one mutation.
    max_generations, patience : int
        Stop after this many generations, or after ``patience`` generations
        without improvement.
    sigma0 : float
        Initial step size as a fraction of C.
    seed : int
        Seed of the strategy's random generator.
    """

    mu: int = 4
    lam: int = 64
    pairs: int = 1
    max_generations: int = 3000
    patience: int = 300
    sigma0: float = 0.5
    seed: object = 0


# Generations whose draws are made and prepared together (fewer when every run stops first).
_BLOCK = 25


@dataclass(frozen=True, eq=False)
class _Runs:
    """Several runs' problems as rows of one padded layout.

    ``K`` (runs, n, n) the kernel matrices and ``KT`` their transposes as
    (runs * n, n) rows, zero-padded to the largest ``n``; ``Y`` (runs * p, n)
    the labels, run r owning rows ``rows[r]`` (its ``p_r`` problems; the rest
    of its ``p`` rows are zeros and never move); ``sizes`` each run's ``n_r``;
    ``run_of_row`` (runs * p,) the run of each row.
    """

    K: np.ndarray
    KT: np.ndarray
    Y: np.ndarray
    rows: list
    sizes: list
    run_of_row: np.ndarray

    @classmethod
    def of(cls, problems) -> _Runs:
        Ks = [np.asarray(K, dtype=np.float64) for K, _ in problems]
        Ys = [np.atleast_2d(np.asarray(Y, dtype=np.float64)) for _, Y in problems]
        sizes = [Y.shape[1] for Y in Ys]
        runs, p, n = len(Ys), max(Y.shape[0] for Y in Ys), max(sizes)
        rows = [slice(r * p, r * p + Y.shape[0]) for r, Y in enumerate(Ys)]
        K = np.zeros((runs, n, n))
        Y = np.zeros((runs * p, n))
        for r in range(runs):
            K[r, : sizes[r], : sizes[r]] = Ks[r]
            Y[rows[r], : sizes[r]] = Ys[r]
        KT = np.ascontiguousarray(K.transpose(0, 2, 1)).reshape(runs * n, n)
        return cls(K, KT, Y, rows, sizes, np.repeat(np.arange(runs), p))


class _Block:
    """The random draws of up to ``count`` generations and everything that depends on them alone.

    Rows are the binary problems of all runs (:class:`_Runs`).
    Each run draws from its own generator, generation by generation, in the
    order a one-generation loop of that run alone would, so a run is the same
    whatever the block size and whatever runs share its block.  The rows of
    a run that has stopped, and rows padding a run with fewer problems, get
    zero draws: they move nothing.  Arrays have a leading generation axis:
    ``coords`` (g, R, lam, m) are the coefficients each offspring moves, i
    then j of each pair; ``sign`` is ``-y_i y_j``, ``up`` where it is
    positive, ``frozen`` the moves that must not happen (i == j, or pairs
    sharing a coefficient); ``Q`` (g, R, lam, m, m) the entries
    ``y_a y_b K_ab`` of the moved coefficients; ``spread`` the log-normal
    factor of the step size, ``step`` the unit steps.  Multiplying by the
    labels (+-1) is exact, so ``Q`` gives the bits of multiplying by them one
    at a time.
    """

    def __init__(self, rngs, running, runs: _Runs, mu, lam, pairs, count):
        R, n = runs.Y.shape
        m = 2 * pairs
        self.parent = np.zeros((count, R, lam), np.int64)
        normal = np.zeros((count, R, lam))
        idx = np.zeros((count, R, lam, m), np.int64)
        self.step = np.zeros((count, R, lam, pairs))
        for r in running:
            rng, own = rngs[r], runs.rows[r]
            q = own.stop - own.start
            draws = [
                (
                    rng.integers(0, mu, size=(q, lam)),
                    rng.standard_normal((q, lam)),
                    rng.integers(0, runs.sizes[r], size=(q, lam, m)),
                    rng.standard_normal((q, lam, pairs)),
                )
                for _ in range(count)
            ]
            for out, drawn in zip((self.parent, normal, idx, self.step), zip(*draws)):
                out[:, own] = drawn
        self.spread = np.exp(1.0 / np.sqrt(2.0 * pairs) * normal)
        self.coords = idx[..., np.r_[0:m:2, 1:m:2]]  # draws (i, j, i, j...) reordered to (i..., j...)
        self.parent_flat = np.arange(R)[:, None] * mu + self.parent
        self.offsets = self.parent_flat[..., None] * n + self.coords  # into the (R, mu, n) population
        self.yc = runs.Y.ravel()[(np.arange(R) * n)[:, None, None] + self.coords]
        self.sign = -self.yc[..., :pairs] * self.yc[..., pairs:]
        self.up = self.sign > 0
        self.frozen = self.coords[..., :pairs] == self.coords[..., pairs:]
        if pairs > 1:
            clash = np.zeros(idx.shape[:-1], bool)
            for a, b in itertools.combinations(range(m), 2):
                clash |= idx[..., a] == idx[..., b]
            self.frozen |= clash[..., None]
        # Row i of each row's run's (n, n) kernel in K, then its entries; signed in place (no new arrays).
        starts = (runs.run_of_row * n * n)[:, None, None] + self.coords * n
        self.Q = runs.K.ravel()[starts[..., :, None] + self.coords[..., None, :]]
        np.multiply(self.Q, self.yc[..., :, None], out=self.Q)
        np.multiply(self.Q, self.yc[..., None, :], out=self.Q)


def solve_duals(problems, C=1.0, strategy: Strategy | None = None, **changes):
    """:func:`solve_dual` on several kernel matrices at once: what each returns alone, bit for bit.

    The runs (e.g. the training folds of a cross-validation) share one
    generation loop, so its cost, which on the experiment's sizes is that of
    calling NumPy rather than of arithmetic, is paid once for all of them;
    each run keeps its own random generator, its own stopping and its own
    result.

    Parameters
    ----------
    problems : sequence of (K, Y)
        Each run's (n_r, n_r) kernel matrix and its (p_r, n_r) labels, as
        :func:`solve_dual` takes them; sizes may differ.
    C, strategy, **changes
        As in :func:`solve_dual`, the same for every run.

    Returns
    -------
    list of (alpha, fitness, generations), one per run, as :func:`solve_dual` returns them.

    Examples
    --------
    >>> K = np.exp(-np.subtract.outer(np.arange(4.0), np.arange(4.0)) ** 2)
    >>> Y = np.array([[1.0, 1.0, -1.0, -1.0]])
    >>> both = solve_duals([(K, Y), (K[:3, :3], Y[:, [0, 2, 3]])], C=10.0)
    >>> bool(np.array_equal(both[0][0], solve_dual(K, Y, C=10.0)[0]))
    True
    """
    es = dataclasses.replace(strategy or Strategy(), **changes)
    mu, lam, pairs, sigma0 = es.mu, es.lam, es.pairs, es.sigma0
    if not problems:
        return []
    layout = _Runs.of(problems)
    runs, (R, n) = len(problems), layout.Y.shape
    Y, rows, sizes = layout.Y, layout.rows, layout.sizes
    rngs = [np.random.default_rng(es.seed) for _ in range(runs)]

    A = np.zeros((R, mu, n))  # parents' coefficients, all start at a = 0
    G = np.ones((R, mu, n))  # gradient 1 - Q a (Q a = y * (K @ (a * y)))
    F = np.zeros((R, mu))  # fitness W(a)
    S = np.full((R, mu), float(sigma0))  # self-adapted step sizes
    # Offsets of each row in flattened (R, x) arrays.
    rows_col = np.arange(R)[:, None]
    row_parents, row_offspring, row_candidates = rows_col * mu, rows_col * lam, rows_col * (mu + lam)
    results = [None] * runs
    stall = np.zeros(runs, np.int64)
    running = list(range(runs))
    generation = 0
    # The loop runs hundreds of generations on small arrays, where each NumPy call costs more than its
    # arithmetic: everything that depends on the random draws alone is computed for a block of generations
    # at once, and the loop keeps only what depends on the population.
    while running and generation < es.max_generations:
        count = min(_BLOCK, es.max_generations - generation)
        block = _Block(rngs, running, layout, mu, lam, pairs, count)
        for t in range(count):
            generation += 1
            parent, coords, yc = block.parent[t], block.coords[t], block.yc[t]
            sigma = np.minimum(np.maximum(S.ravel()[block.parent_flat[t]] * block.spread[t], 1e-6), 1.0)
            step = sigma[..., None] * C * block.step[t]
            # Repair: moving a_i by t moves a_j by -y_i y_j t; clip t to keep both in [0, C].
            ac = A.ravel()[block.offsets[t]]
            ai, aj = ac[..., :pairs], ac[..., pairs:]
            up = block.up[t]
            lo_j = np.where(up, -aj, aj - C)
            hi_j = np.where(up, C - aj, aj)
            step = np.minimum(np.maximum(step, np.maximum(-ai, lo_j)), np.minimum(C - ai, hi_j))
            step = np.where(block.frozen[t], 0.0, step)
            delta = np.concatenate([step, block.sign[t] * step], axis=2)  # moves of coefficients (i..., j...)
            g = G.ravel()[block.offsets[t]]
            # W(a + d) - W(a) = g.d - 1/2 d^T Q d over the few touched coordinates.
            qd = np.einsum("plab,plb->pla", block.Q[t], delta)
            # np.add.reduce is ndarray.sum without its Python layer.
            gain = np.add.reduce(g * delta, axis=2) - 0.5 * np.add.reduce(delta * qd, axis=2)
            cand_F = np.concatenate([F, F.ravel()[block.parent_flat[t]] + gain], axis=1)
            best = np.argsort(-cand_F, axis=1, kind="stable")[:, :mu]
            kept = cand_F.ravel()[best + row_candidates]
            # Rows of F are sorted, best first.  Rows that do not move never improve.
            improved = (kept[:, 0] > F[:, 0] + 1e-12).reshape(runs, -1).any(axis=1)
            from_child = best >= mu
            child = np.where(from_child, best - mu, 0) + row_offspring
            src = np.where(from_child, parent.ravel()[child], best) + row_parents
            newA = A.reshape(R * mu, n)[src]
            newG = G.reshape(R * mu, n)[src]
            newS = np.where(from_child, sigma.ravel()[child], S.ravel()[np.minimum(best, mu - 1) + row_parents])
            pp, mm = np.nonzero(from_child)
            if len(pp):
                cc = child[pp, mm]  # flat (R * lam) offspring
                cidx = coords.reshape(R * lam, -1)[cc]  # (q, m)
                cdel = delta.reshape(R * lam, -1)[cc]
                at = ((pp * mu + mm) * n)[:, None] + cidx
                # Only the moved coefficients can leave the box.
                newA.ravel()[at] = np.minimum(np.maximum(newA.ravel()[at] + cdel, 0.0), C)
                # G -= Q[:, c] * d_c  with Q[:, c] = y * y_c * K[:, c]
                w = yc.reshape(R * lam, -1)[cc] * cdel
                kcols = layout.KT[(layout.run_of_row[pp] * n)[:, None] + cidx]  # (q, m, n): each run's K[:, c]
                newG.reshape(R * mu, n)[pp * mu + mm] -= Y[pp] * np.einsum("qmn,qm->qn", kcols, w)
            A, G, S = newA, newG, newS
            F = kept
            stall = np.where(improved, 0, stall + 1)
            for r in [r for r in running if stall[r] >= es.patience]:
                results[r] = _best_of(A[rows[r]], F[rows[r]], sizes[r], generation)
                running.remove(r)
            if not running:
                break
    for r in running:  # the generation cap
        results[r] = _best_of(A[rows[r]], F[rows[r]], sizes[r], generation)
    return results


def _best_of(A, F, n, generation):
    """A run's result from its population: each problem's fittest parent, cut to the run's size."""
    top = np.argmax(F, axis=1)
    rows = np.arange(len(F))
    return A[rows, top, :n], F[rows, top], generation  # fancy indexing copies


def solve_dual(K, Y, C=1.0, strategy: Strategy | None = None, **changes):
    """Solve several SVM duals sharing one kernel matrix with a (mu+lambda)-ES.

    Parameters
    ----------
    K : (n, n) float64
        Kernel matrix of the training samples.
    Y : (p, n) float64
        One row of +-1 labels per binary problem (one-vs-rest: one per class).
    C : float
        Box constraint.
    strategy : Strategy, optional
        The strategy's settings (default ``Strategy()``), changed by any
        ``**changes`` named as its fields (``max_generations=4000``...).

    Returns
    -------
    alpha : (p, n) float64
        The best coefficient vector found for each problem; every row is
        feasible (inside [0, C], ``alpha @ y == 0``).
    fitness : (p,) float64
        Its dual objective W.
    generations : int
        Generations run.

    Examples
    --------
    >>> K = np.exp(-np.subtract.outer(np.arange(4.0), np.arange(4.0)) ** 2)
    >>> a, w, _ = solve_dual(K, np.array([[1.0, 1.0, -1.0, -1.0]]), C=10.0)
    >>> bool(abs(a[0] @ [1, 1, -1, -1]) < 1e-9 and w[0] > 0)
    True
    """
    return solve_duals([(K, Y)], C, strategy, **changes)[0]
