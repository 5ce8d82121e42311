"""Mierswa's evolutionary SVM: a kernel SVM whose dual an evolution strategy solves.

The paper's recognition used RapidMiner's *Evolutionary SVM* operator
(I. Mierswa, "Evolutionary learning with kernels: a generic solution for large
margin problems", GECCO 2006), which keeps the kernel SVM's dual problem but
replaces the SMO solver by an evolution strategy
(:mod:`classify.recognizers.evolution_strategy`: :class:`Strategy`,
:func:`solve_dual`, :func:`solve_duals`, importable from here too).
:class:`EvolutionarySVM` is the scikit-learn estimator around it: an RBF
kernel, one dual per one-vs-rest problem, support vectors and biases.

The bias b is the mean of ``y_i - sum_j a_j y_j k(x_j, x_i)`` over the free
support vectors (0 < a_i < C), or the middle of the feasible interval when
there are none, as in LIBSVM.
"""

from __future__ import annotations

import numbers

import numpy as np
from sklearn.base import BaseEstimator, ClassifierMixin, clone
from sklearn.metrics.pairwise import rbf_kernel
from sklearn.utils import check_array, column_or_1d
from sklearn.utils.multiclass import check_classification_targets
from sklearn.utils.validation import check_is_fitted

from classify.recognizers.evolution_strategy import Strategy, solve_dual, solve_duals

__all__ = ["EvolutionarySVM", "Strategy", "solve_dual", "solve_duals", "as_labels", "as_matrix", "check_n_features"]


def as_matrix(X, name="X"):
    """Imprints as rows of a float64 matrix: (N, d) stays, (N, rows, cols) is flattened row-major.

    Every classifier of this package accepts either shape, so an
    ``ImprintSet.imprints`` array can be passed as it is.  Input is checked
    as scikit-learn checks it (:func:`sklearn.utils.check_array`, with its
    messages): no sparse or complex data, no NaN or infinity, no sample or
    feature missing, and one sample is ``(1, d)``, not ``(d,)``.

    Examples
    --------
    >>> as_matrix(np.zeros((2, 16, 16))).shape
    (2, 256)
    """
    X = check_array(X, dtype=np.float64, allow_nd=True, input_name=name)
    X = X.reshape(len(X), -1)
    if X.shape[1] == 0:
        raise ValueError(f"Found array with 0 feature(s) (shape={X.shape}) while a minimum of 1 is required.")
    return X


def as_labels(y, n_samples: int, estimator: str):
    """Class labels of ``n_samples`` rows as a (n_samples,) array; a column ``(n, 1)`` is raveled with a warning.

    Raises ValueError, its message led by ``estimator`` (a name), for another
    length, and for targets that are no class labels (continuous values:
    "Unknown label type") as scikit-learn does.

    Examples
    --------
    >>> as_labels(["cup", "cow"], 2, "KNN").tolist()
    ['cup', 'cow']
    """
    y = column_or_1d(y, warn=True)
    if y.shape != (n_samples,):
        raise ValueError(f"{estimator}: y must have shape ({n_samples},), got {y.shape}")
    check_classification_targets(y)
    return y


def check_n_features(estimator, X) -> None:
    """Refuse ``X`` (N, d) whose d is not the ``n_features_in_`` the estimator was fitted with."""
    if X.shape[1] != estimator.n_features_in_:
        raise ValueError(
            f"X has {X.shape[1]} features, but {type(estimator).__name__} is expecting "
            f"{estimator.n_features_in_} features as input"
        )


class EvolutionarySVM(ClassifierMixin, BaseEstimator):
    """Kernel SVM whose dual is solved by an evolution strategy, one-vs-rest over classes.

    Parameters
    ----------
    C : float
        Box constraint, as in :class:`sklearn.svm.SVC`.
    gamma : float or "scale"
        RBF kernel width ``k(x, z) = exp(-gamma |x - z|^2)``; ``"scale"`` is
        ``1 / (n_features * X.var())`` as in SVC.
    mu, lam, pairs, max_generations, patience, sigma0 :
        The strategy's settings (see :func:`solve_dual`).
    random_state : int
        Seed of the strategy.

    Attributes
    ----------
    classes_ : (n_classes,) labels
    support_vectors_ : (n_sv, d) training samples with a non-zero coefficient in any problem
    dual_coef_ : (n_problems, n_sv) ``a_i * y_i`` per one-vs-rest problem
    intercept_ : (n_problems,) biases
    fitness_ : (n_problems,) dual objective reached
    n_generations_ : int

    Notes
    -----
    Two classes give one binary problem; more give one problem per class
    (that class +1, the rest -1) and ``predict`` takes the class with the
    largest decision value.  ``predict_proba`` is the softmax of the one-vs-rest
    decision values (for two classes, of ``(-f, f)``): monotone in them, so its
    argmax is ``predict``, and never exactly 0 or 1, so posteriors of several
    touches can be multiplied.  It is not calibrated.

    Inputs are (N, d) vectors or (N, rows, cols) imprints, flattened.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> X = np.r_[rng.normal(0, 1, (20, 2)), rng.normal(4, 1, (20, 2))]
    >>> y = np.repeat([0, 1], 20)
    >>> EvolutionarySVM(C=1.0).fit(X, y).score(X, y)
    1.0
    """

    def __init__(
        self, C=1.0, gamma="scale", mu=4, lam=64, pairs=2, max_generations=600, patience=60, sigma0=0.5, random_state=0
    ):
        self.C = C
        self.gamma = gamma
        self.mu = mu
        self.lam = lam
        self.pairs = pairs
        self.max_generations = max_generations
        self.patience = patience
        self.sigma0 = sigma0
        self.random_state = random_state

    def _check_params(self):
        if not (isinstance(self.C, numbers.Real) and self.C > 0):
            raise ValueError(f"EvolutionarySVM: C must be a positive number, got {self.C!r}")
        if not (self.gamma == "scale" or (isinstance(self.gamma, numbers.Real) and self.gamma > 0)):
            raise ValueError(f"EvolutionarySVM: gamma must be 'scale' or a positive number, got {self.gamma!r}")
        for name in ("mu", "lam", "pairs", "max_generations", "patience"):
            value = getattr(self, name)
            if not (isinstance(value, numbers.Integral) and value >= 1):
                raise ValueError(f"EvolutionarySVM: {name} must be a positive integer, got {value!r}")

    def fit(self, X, y):
        """Fit one dual per one-vs-rest problem; X is (N, d) or (N, rows, cols)."""
        self._check_params()
        X, K, Y = self._problem(X, y)
        return self._adopt(X, K, Y, solve_dual(K, Y, float(self.C), self._strategy()))

    def fit_each(self, sets):
        """Clones of this estimator fitted on each ``(X, y)`` of ``sets``, their duals solved together.

        Each model is the one ``clone(self).fit(X, y)`` gives, bit for bit
        (:func:`solve_duals`), in a fraction of the time when the sets are
        the folds of a cross-validation.

        Examples
        --------
        >>> X = np.array([[0.0], [0.2], [3.0], [3.2], [0.1], [3.1]])
        >>> y = np.array([0, 0, 1, 1, 0, 1])
        >>> a, b = EvolutionarySVM(C=10.0).fit_each([(X[:4], y[:4]), (X[2:], y[2:])])
        >>> bool(np.array_equal(b.dual_coef_, EvolutionarySVM(C=10.0).fit(X[2:], y[2:]).dual_coef_))
        True
        """
        self._check_params()
        models = [clone(self) for _ in sets]
        problems = [m._problem(X, y) for m, (X, y) in zip(models, sets)]
        solutions = solve_duals([(K, Y) for _, K, Y in problems], float(self.C), self._strategy())
        return [m._adopt(*problem, solution) for m, problem, solution in zip(models, problems, solutions)]

    def _strategy(self) -> Strategy:
        return Strategy(
            self.mu, self.lam, self.pairs, self.max_generations, self.patience, self.sigma0, self.random_state
        )

    def _problem(self, X, y):
        """Checked ``X``, its kernel matrix and the one-vs-rest labels; sets ``classes_``."""
        X = as_matrix(X)
        y = as_labels(y, len(X), "EvolutionarySVM")
        self.classes_, codes = np.unique(y, return_inverse=True)
        if len(self.classes_) < 2:
            raise ValueError(f"EvolutionarySVM: needs samples of at least two classes, got {len(self.classes_)} class")
        if self.gamma == "scale":
            var = X.var()
            self._gamma = 1.0 / (X.shape[1] * var) if var > 0 else 1.0
        else:
            self._gamma = float(self.gamma)
        K = rbf_kernel(X, gamma=self._gamma)
        if len(self.classes_) == 2:
            Y = np.where(codes == 1, 1.0, -1.0)[None]
        else:
            Y = np.where(codes[None, :] == np.arange(len(self.classes_))[:, None], 1.0, -1.0)
        return X, K, Y

    def _adopt(self, X, K, Y, solution):
        """Take the duals' solution: support vectors, coefficients and biases."""
        alpha, self.fitness_, self.n_generations_ = solution
        self.intercept_ = np.array([_bias(K, a, yy, float(self.C)) for a, yy in zip(alpha, Y)])
        used = (alpha > 0).any(axis=0)
        self.support_ = np.flatnonzero(used)
        self.support_vectors_ = X[used]
        self.dual_coef_ = (alpha * Y)[:, used]
        self.n_features_in_ = X.shape[1]
        return self

    def decision_function(self, X):
        """(N,) for two classes (positive means ``classes_[1]``), else (N, n_classes)."""
        check_is_fitted(self, "dual_coef_")
        X = as_matrix(X)
        check_n_features(self, X)
        if len(self.support_vectors_):
            f = rbf_kernel(X, self.support_vectors_, gamma=self._gamma) @ self.dual_coef_.T + self.intercept_
        else:
            f = np.tile(self.intercept_, (len(X), 1))
        return f[:, 0] if len(self.classes_) == 2 else f

    def predict(self, X):
        f = self.decision_function(X)
        if f.ndim == 1:
            return self.classes_[(f > 0).astype(int)]
        return self.classes_[np.argmax(f, axis=1)]

    def predict_proba(self, X):
        """Softmax of the one-vs-rest decision values (see Notes)."""
        f = self.decision_function(X)
        if f.ndim == 1:
            f = np.stack([-f, f], axis=1)
        z = np.exp(f - f.max(axis=1, keepdims=True))
        return z / z.sum(axis=1, keepdims=True)


def _bias(K, alpha, y, C):
    """The SVM bias: mean over free support vectors, else the middle of the feasible range."""
    grad = y - K @ (alpha * y)  # y_i - sum_j a_j y_j k_ij, equal to b at free SVs
    eps = 1e-8 * C
    free = (alpha > eps) & (alpha < C - eps)
    if free.any():
        return float(grad[free].mean())
    # KKT bounds: at a = 0, y_i f_i >= 1; at a = C, y_i f_i <= 1.
    up = ((y > 0) & (alpha <= eps)) | ((y < 0) & (alpha >= C - eps))
    lo = ((y < 0) & (alpha <= eps)) | ((y > 0) & (alpha >= C - eps))
    hi_b = grad[lo].min() if lo.any() else np.inf
    lo_b = grad[up].max() if up.any() else -np.inf
    if np.isfinite(hi_b) and np.isfinite(lo_b):
        return float((hi_b + lo_b) / 2)
    return float(hi_b if np.isfinite(hi_b) else lo_b if np.isfinite(lo_b) else 0.0)
