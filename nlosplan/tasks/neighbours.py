"""k nearest neighbours on principal components of square-root counts: a learner that needs no training time.

A capture is compared with every training capture after the square root of its counts (the variance-stabilising
transform of Poisson counts: every bin's noise is then about 1/2 whatever its level) and a projection on the
training captures' leading principal components (the directions the scenes vary along; the thousand-odd other
directions carry mostly counting noise, which otherwise dominates a Euclidean distance); the answer is the mean
position (localization) or the vote share per class (shape, size) of its ``k`` nearest training captures. The
number of components (:data:`COMPONENT_CHOICES`) and ``k`` (:data:`K_CHOICES`) are chosen together on a seeded
validation part of the training captures (15 %, stratified for classes, the share the networks hold out for early
stopping), then the components are refitted on every training capture and every one is a neighbour.
The components are the exact eigenvectors of the captures' scatter matrix up to :data:`COVARIANCE_MAX_DIM` values
a capture (one (D, D) product serves both fits), scikit-learn's randomized PCA for longer captures (8x8 zones);
scikit-learn's brute-force neighbours do the search.

Measured on the main job's DENALI reference (30 objects, 2,100 training captures, DENALI's design, seed 0): the
projection takes localization from 6.2 to 4.4 cm, shape from 25 to 33-38 % and size from 91 to 96 %
(``docs/design-planner.md``, "The learners").

Why here: on the design's simulated DENALI world the networks, trained for seconds on a few thousand captures,
stay far below DENALI's recipe; this learner reaches its answer in well under a second and is at least as good at
those budgets (``docs/design-planner.md``, "The learners"). It is one of the design's candidate learners
(:data:`~nlosplan.tasks.names.LEARNER_NAMES`), not a DENALI benchmark model.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from nlosplan.errors import UserError
from nlosplan.tasks.targets import encode_targets

__all__ = ["COMPONENT_CHOICES", "K_CHOICES", "NeighbourModel", "fit_neighbours", "root_counts"]

#: Neighbour counts the validation part chooses among.
K_CHOICES = (1, 3, 5, 9, 15)
#: Principal components the validation part chooses among (those above the fit part's rank are skipped).
COMPONENT_CHOICES = (4, 8, 12, 16, 24, 32)
#: Longest capture (zones x bins) whose principal components are the exact eigenvectors of its scatter matrix
#: (one (D, D) product: cheaper than scikit-learn's randomized PCA, fitted twice, up to about this length; 3x3 x 128
#: is 1,152); longer captures use the randomized PCA.
COVARIANCE_MAX_DIM = 1536
#: Components and neighbours when too few captures leave no validation part.
DEFAULT_COMPONENTS, DEFAULT_K = 16, 5


def root_counts(histograms) -> np.ndarray:
    """``sqrt(max(counts, 0))`` flattened per capture: (N, rows, cols, bins) -> (N, rows * cols * bins) float32."""
    x = np.asarray(histograms, dtype=np.float32)
    if x.ndim != 4:
        raise UserError(f"histograms must be (N, rows, cols, bins), got {x.shape}")
    return np.sqrt(np.maximum(x, 0.0)).reshape(len(x), -1)


@dataclass(eq=False)
class NeighbourModel:
    """A fitted k-nearest-neighbour learner (:func:`fit_neighbours`).

    Attributes
    ----------
    task : {"loc", "shape", "size"}
    k : int
        Neighbours per answer (chosen on the validation part).
    components : int
        Principal components of the square-root counts the distance is measured in (chosen with ``k``).
    classes : tuple of str or None
        Class names in output order (None for localization).
    history : list of dict
        The validation score of every pair tried: ``{"components", "k", "val_score"}`` (RMSE in metres, or the
        error rate).
    n_train, n_val : int
        Training captures that are neighbours (all of them), and the validation part that chose ``k``.
    train_seconds : float
    """

    task: str
    k: int
    components: int
    classes: tuple[str, ...] | None
    history: list[dict] = field(default_factory=list)
    n_train: int = 0
    n_val: int = 0
    train_seconds: float = 0.0
    _search: object = None
    _project: object = None

    def predict(self, histograms) -> np.ndarray:
        """(N, 2) mean (x, y) of the neighbours in metres (localization), or (N, classes) vote shares."""
        x = self._project(root_counts(histograms))
        if self.task == "loc":
            return np.asarray(self._search.predict(x), dtype=np.float64)
        return np.asarray(self._search.predict_proba(x), dtype=np.float64)


def _estimator(task: str, k: int):
    from sklearn.neighbors import KNeighborsClassifier, KNeighborsRegressor

    cls = KNeighborsRegressor if task == "loc" else KNeighborsClassifier
    return cls(n_neighbors=k, algorithm="brute")


def _nearest(a: np.ndarray, b: np.ndarray, k: int) -> np.ndarray:
    """(len(b), k) indices into ``a`` of each row of ``b``'s k nearest rows, nearest first (brute force)."""
    from sklearn.neighbors import NearestNeighbors

    return NearestNeighbors(n_neighbors=k, algorithm="brute").fit(a).kneighbors(b, return_distance=False)


def _val_score(task: str, near: np.ndarray, y: np.ndarray) -> float:
    """The validation score of answers from the neighbours' targets ``near`` (N, k[, 2]): the RMSE of their mean
    position in metres, or the error rate of their majority class (ties to the lowest class, as scikit-learn)."""
    if task == "loc":
        return float(np.sqrt(np.mean((near.mean(axis=1) - y) ** 2)))
    votes = np.zeros((len(near), int(max(near.max(), y.max())) + 1))
    np.add.at(votes, (np.arange(len(near))[:, None], near), 1.0)
    return float(np.mean(votes.argmax(axis=1) != y))


class _Projection:
    """Centring and projection on the leading principal components: (N, D) -> (N, components) float32.

    ``mean`` (D,) and ``basis`` (D, components), leading component first.
    """

    def __init__(self, mean: np.ndarray, basis: np.ndarray):
        self.mean = np.asarray(mean, np.float32)
        self.basis = np.asarray(basis, np.float32)

    @classmethod
    def fit(cls, x: np.ndarray, components: int, seed: int) -> "_Projection":
        """scikit-learn's PCA of ``x`` (N, D) (randomized for long captures)."""
        from sklearn.decomposition import PCA

        pca = PCA(n_components=components, random_state=int(seed) % 2**32).fit(x)
        return cls(pca.mean_, pca.components_.T)

    @classmethod
    def of_scatter(cls, mean: np.ndarray, scatter: np.ndarray, components: int) -> "_Projection":
        """The leading eigenvectors of a scatter matrix (D, D) about ``mean`` (D,): an exact PCA."""
        from scipy.linalg import eigh

        d = len(scatter)
        _, vectors = eigh(scatter, subset_by_index=[d - components, d - 1])
        return cls(mean, vectors[:, ::-1])

    def __call__(self, x: np.ndarray, components: int | None = None) -> np.ndarray:
        basis = self.basis if components is None else self.basis[:, :components]
        return (x - self.mean) @ basis


@dataclass(frozen=True, eq=False)
class _Moments:
    """Sums of a set of captures about a shift, float64: ``n``, ``shift`` (D,), ``total`` (D,), ``scatter`` (D, D).

    Two sets' moments add up to their union's, so the fit part's and all captures' principal components come
    from one (D, D) product over each capture (:data:`COVARIANCE_MAX_DIM`).
    """

    n: int
    shift: np.ndarray
    total: np.ndarray
    scatter: np.ndarray

    @classmethod
    def of(cls, x: np.ndarray, shift: np.ndarray) -> "_Moments":
        """The moments of captures ``x`` (N, D) about ``shift`` (D,)."""
        xc = x - shift
        return cls(len(x), shift.astype(np.float64), xc.sum(axis=0, dtype=np.float64),
                   (xc.T @ xc).astype(np.float64))   # a float32 product of centred values

    def __add__(self, other: "_Moments") -> "_Moments":
        if not np.array_equal(self.shift, other.shift):
            raise ValueError("moments about different shifts do not add up")
        return _Moments(self.n + other.n, self.shift, self.total + other.total, self.scatter + other.scatter)

    def projection(self, components: int) -> _Projection:
        d = self.total / self.n   # the mean's offset from the shift
        return _Projection.of_scatter(self.shift + d, self.scatter - self.n * np.outer(d, d), components)


def fit_neighbours(histograms, targets, *, task: str, classes=None, seed: int = 42,
                   val_fraction: float = 0.15) -> NeighbourModel:
    """Fit the k-nearest-neighbour learner on training captures.

    Parameters
    ----------
    histograms : array_like, shape (N, rows, cols, bins)
        Counts of the training captures.
    targets : array_like
        (N, 2) (x, y) in metres for ``task="loc"``; (N,) class labels (stored as str) otherwise.
    task : {"loc", "shape", "size"}
    classes : sequence of str, optional
        Class names in output order (default: the sorted distinct training labels); the vote shares of
        :meth:`NeighbourModel.predict` follow it, with 0 for a class no training capture has.
    seed : int
        Seed of the validation part.
    val_fraction : float
        Part of the training captures that chooses the components and ``k`` (then they are neighbours too).

    Raises
    ------
    UserError
        Fewer than 2 training captures, mismatched targets, a label outside ``classes``.
    """
    from sklearn.model_selection import train_test_split

    t0 = time.perf_counter()
    x = root_counts(histograms)
    n = len(x)
    if n < 2:
        raise UserError(f"k nearest neighbours need at least 2 training captures, got {n}")
    y, names = encode_targets(task, targets, n, classes)
    strat = None
    if names is not None:
        _, counts = np.unique(y, return_counts=True)
        strat = y if counts.min() >= 2 else None
    n_val = int(round(val_fraction * n))
    history = []
    moments_ok, moments = x.shape[1] <= COVARIANCE_MAX_DIM, None
    c_best, k_best = min(DEFAULT_COMPONENTS, n - 1, x.shape[1]), min(DEFAULT_K, n)
    if n_val >= 1 and n - n_val >= 2:
        try:
            fit, val = train_test_split(np.arange(n), test_size=n_val, stratify=strat, random_state=int(seed) % 2**32)
        except ValueError:  # a class too small for a stratified part
            fit, val = train_test_split(np.arange(n), test_size=n_val, random_state=int(seed) % 2**32)
        rank = min(len(fit) - 1, x.shape[1])
        choices = [c for c in COMPONENT_CHOICES if c <= rank] or [rank]
        if moments_ok:
            shift = x[fit].mean(axis=0)
            moments = (_Moments.of(x[fit], shift), _Moments.of(x[val], shift))
            proj = moments[0].projection(max(choices))
        else:
            proj = _Projection.fit(x[fit], max(choices), seed)
        ks = [k for k in K_CHOICES if k <= len(fit)]
        for c in choices:   # one neighbour search per component count; every k reads its first k neighbours
            order = _nearest(proj(x[fit], c), proj(x[val], c), max(ks))
            for k in ks:
                history.append({"components": c, "k": k, "val_score": _val_score(task, y[fit][order[:, :k]], y[val])})
        best = min(history, key=lambda h: (h["val_score"], h["components"], h["k"]))
        c_best, k_best = best["components"], best["k"]
    else:
        n_val = 0
    if moments is not None:
        project = (moments[0] + moments[1]).projection(c_best)
    elif moments_ok:
        project = _Moments.of(x, x.mean(axis=0)).projection(c_best)
    else:
        project = _Projection.fit(x, c_best, seed)
    est = _estimator(task, k_best).fit(project(x), y)
    if names is not None and len(est.classes_) < len(names):
        est = _padded(est, len(names))
    return NeighbourModel(task, int(k_best), int(c_best), names, history, n_train=n, n_val=n_val,
                          train_seconds=time.perf_counter() - t0, _search=est, _project=project)


class _padded:
    """A fitted classifier whose vote shares cover every class (classes no training capture has get 0)."""

    def __init__(self, est, n_classes: int):
        self.est, self.n_classes = est, n_classes

    def predict_proba(self, x) -> np.ndarray:
        p = self.est.predict_proba(x)
        out = np.zeros((len(p), self.n_classes))
        out[:, np.asarray(self.est.classes_, dtype=np.int64)] = p
        return out
