"""k nearest neighbours on principal components of square-root counts: the design's learner that needs no training time."""

import numpy as np
import pytest

from nlosplan.errors import UserError
from nlosplan.tasks.metrics import loc_rmse, top1_accuracy
from nlosplan.tasks.neighbours import COMPONENT_CHOICES, K_CHOICES, fit_neighbours, root_counts


def captures(n_per, rng, classes=("a", "b", "c"), level=50.0):
    """Poisson captures (1 x 1 zone x 16 bins) whose peak bin tells the class, and whose peak height the position."""
    x, y, xy = [], [], []
    for i, c in enumerate(classes):
        for _ in range(n_per):
            pos = rng.uniform(0, 0.3)
            lam = np.full(16, 20.0)
            lam[3 + 4 * i] += level * (1 + 10 * pos)
            x.append(rng.poisson(lam))
            y.append(c)
            xy.append((pos, 0.3 - pos))
    return np.array(x, float).reshape(-1, 1, 1, 16), np.array(y), np.array(xy)


def test_classes_are_told_apart_and_the_votes_follow_the_class_order():
    rng = np.random.default_rng(0)
    x, y, _ = captures(40, rng)
    xt, yt, _ = captures(20, rng)
    m = fit_neighbours(x, y, task="shape", classes=("a", "b", "c", "d"), seed=1)
    p = m.predict(xt)
    assert p.shape == (60, 4)
    assert np.allclose(p.sum(axis=1), 1.0) and np.all(p[:, 3] == 0)   # "d": no training capture, no vote
    truth = np.array([("a", "b", "c", "d").index(v) for v in yt])
    assert top1_accuracy(p, truth) > 0.95
    assert m.k in K_CHOICES and m.n_train == 120 and m.n_val == 18
    # every pair of components (up to the 16 bins) and k is tried on the validation part
    pairs = [(h["components"], h["k"]) for h in m.history]
    assert pairs == [(c, k) for c in COMPONENT_CHOICES if c <= 16 for k in K_CHOICES]


def test_positions_are_regressed_and_k_is_chosen_on_the_validation_part():
    rng = np.random.default_rng(1)
    x, _, xy = captures(150, rng, classes=("a",), level=400.0)
    xt, _, xyt = captures(50, rng, classes=("a",), level=400.0)
    m = fit_neighbours(x, xy, task="loc", seed=3)
    pred = m.predict(xt)
    assert pred.shape == (50, 2)
    # far better than predicting the mean position (about 8.7 cm here)
    assert loc_rmse(pred, xyt) < 0.3 * loc_rmse(np.broadcast_to(xy.mean(0), xyt.shape), xyt)
    best = min(m.history, key=lambda h: (h["val_score"], h["components"], h["k"]))
    assert (m.components, m.k) == (best["components"], best["k"])
    # the same seed gives the same learner
    again = fit_neighbours(x, xy, task="loc", seed=3)
    assert again.k == m.k and np.array_equal(again.predict(xt), pred)


def test_principal_components_keep_the_distance_off_the_noise():
    """A position told by one peak among 400 noise-only bins: the projection finds it, raw distances drown it."""
    from sklearn.neighbors import KNeighborsRegressor

    rng = np.random.default_rng(4)

    def wide(n):
        pos = rng.uniform(0, 0.3, n)
        lam = np.full((n, 400), 30.0)
        lam[:, 7] += 300 * pos
        lam[:, 8] += 300 * (0.3 - pos)
        return rng.poisson(lam).astype(float).reshape(n, 1, 1, 400), np.stack([pos, 0.3 - pos], 1)

    x, xy = wide(300)
    xt, xyt = wide(100)
    m = fit_neighbours(x, xy, task="loc", seed=0)
    raw = KNeighborsRegressor(m.k, algorithm="brute").fit(root_counts(x), xy).predict(root_counts(xt))
    assert m.components < 16
    assert loc_rmse(m.predict(xt), xyt) < 0.75 * loc_rmse(raw, xyt)   # 2.4 against 3.7 cm


def test_two_captures_leave_no_validation_part():
    x = np.arange(8.0).reshape(2, 1, 1, 4) ** 2
    m = fit_neighbours(x, np.array([[0.0, 0.1], [0.2, 0.3]]), task="loc")
    assert (m.components, m.k, m.n_val, m.history) == (1, 2, 0, [])
    np.testing.assert_allclose(m.predict(x), [[0.1, 0.2], [0.1, 0.2]])


def test_root_counts_stabilise_the_poisson_noise():
    rng = np.random.default_rng(2)
    lam = np.array([25.0, 100.0, 10_000.0])
    x = rng.poisson(np.broadcast_to(lam, (20_000, 3))).reshape(-1, 1, 1, 3)
    sd = root_counts(x).std(axis=0)
    assert np.allclose(sd, 0.5, atol=0.04)   # about 1/2 at every level: plain distances weigh bins alike
    assert root_counts(np.full((1, 1, 1, 2), -3.0)).tolist() == [[0.0, 0.0]]


def test_bad_training_sets_are_refused():
    x = np.ones((5, 1, 1, 4))
    with pytest.raises(UserError, match="at least 2 training captures"):
        fit_neighbours(x[:1], np.zeros((1, 2)), task="loc")
    with pytest.raises(UserError, match=r"localization targets must be \(N, 2\)"):
        fit_neighbours(x, np.zeros(5), task="loc")
    with pytest.raises(UserError, match="training labels z are not among the classes"):
        fit_neighbours(x, np.array(list("aabbz")), task="size", classes=("a", "b"))
    with pytest.raises(UserError, match=r"histograms must be \(N, rows, cols, bins\)"):
        root_counts(np.ones((5, 4)))


def test_the_validation_scores_equal_scikit_learn_s_estimators_at_every_k():
    """One neighbour search per component count, every k read from it: the same answers as a fit per k."""
    from sklearn.neighbors import KNeighborsClassifier, KNeighborsRegressor

    from nlosplan.tasks.neighbours import _nearest, _val_score

    rng = np.random.default_rng(5)
    a, b = rng.normal(size=(300, 6)), rng.normal(size=(80, 6))
    xy, xy_val = rng.uniform(0, 0.3, (300, 2)), rng.uniform(0, 0.3, (80, 2))
    cls, cls_val = rng.integers(0, 4, 300), rng.integers(0, 4, 80)
    order = _nearest(a, b, 15)
    for k in K_CHOICES:
        pred = KNeighborsRegressor(k, algorithm="brute").fit(a, xy).predict(b)
        assert _val_score("loc", xy[order[:, :k]], xy_val) == pytest.approx(np.sqrt(np.mean((pred - xy_val) ** 2)))
        label = KNeighborsClassifier(k, algorithm="brute").fit(a, cls).predict(b)
        assert _val_score("shape", cls[order[:, :k]], cls_val) == pytest.approx(np.mean(label != cls_val))


def test_scatter_components_equal_pca_and_two_parts_add_up_to_their_union():
    # short captures take their components from one scatter matrix per part (the fit part's, then the union's
    # by adding the validation part's): the same subspace as a PCA of the union, so the same distances
    from nlosplan.tasks.neighbours import COVARIANCE_MAX_DIM, _Moments, _Projection

    rng = np.random.default_rng(5)
    latent = rng.normal(size=(400, 6)) * np.array([9.0, 7.0, 5.0, 4.0, 3.0, 2.0])
    x = (latent @ rng.normal(size=(6, 96)) + 30.0 + rng.normal(scale=0.1, size=(400, 96))).astype(np.float32)
    assert x.shape[1] <= COVARIANCE_MAX_DIM
    shift = x[:300].mean(axis=0)
    union = _Moments.of(x[:300], shift) + _Moments.of(x[300:], shift)
    whole = _Moments.of(x, x.mean(axis=0))
    assert union.n == 400 and np.allclose(union.shift + union.total / 400, x.mean(axis=0), atol=1e-4)
    ours, exact = union.projection(6), _Projection.fit(x.astype(np.float64), 6, seed=0)
    np.testing.assert_allclose(np.abs(ours.basis.T @ exact.basis), np.eye(6), atol=1e-3)   # same axes, up to sign
    np.testing.assert_allclose(np.abs(whole.projection(6).basis.T @ exact.basis), np.eye(6), atol=1e-3)
    a, b = ours(x), exact(x).astype(np.float32)
    d_ours = np.linalg.norm(a[:, None] - a[None], axis=-1)
    d_exact = np.linalg.norm(b[:, None] - b[None], axis=-1)
    assert np.abs(d_ours - d_exact).max() <= 1e-3 * d_exact.max()
    with pytest.raises(ValueError, match="moments about different shifts do not add up"):
        _Moments.of(x[:300], shift) + _Moments.of(x[300:], shift + 1.0)
