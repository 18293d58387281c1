"""A small synthetic counts model for capture-planner tests (no simulator: fast and exact)."""

import numpy as np

from nlosplan.planner.capture.space import CandidateSpace

BINS = 24


def synthetic_space(n: int = 5, repeats: int = 3, step: float = 80.0) -> CandidateSpace:
    """``n x n`` candidates (mm) whose object return is a Gaussian pulse; time and zone split encode (x, y)."""
    xs = np.arange(n) * step
    pts = np.array([(x, y) for y in xs for x in xs], dtype=np.float64)
    labels = pts / 1000.0 + np.array([1.0, 0.2])
    t = np.arange(BINS, dtype=np.float64)
    c = len(pts)
    direct = np.zeros((c, 2, BINS))
    direct[:, :, 2] = 5000.0
    background = np.full((c, 2, BINS), 2.0)
    obj = np.zeros((c, 2, BINS))
    jac = np.zeros((c, 2, BINS, 2))
    for i, (x, y) in enumerate(labels):
        centre = 6.0 + 40.0 * (x - 1.0) + 20.0 * (y - 0.2)
        share = np.array([0.5 + (x - 1.16), 0.5 - (x - 1.16)])
        pulse = 400.0 * np.exp(-0.5 * (t - centre) ** 2)
        dpulse = pulse * (t - centre)               # d pulse / d centre
        obj[i] = share[:, None] * pulse[None]
        jac[i, :, :, 0] = share[:, None] * dpulse[None] * 40.0 + np.array([1.0, -1.0])[:, None] * pulse[None]
        jac[i, :, :, 1] = share[:, None] * dpulse[None] * 20.0
    return CandidateSpace(points_mm=pts, labels_xy=labels, direct=direct.reshape(c, -1), object=obj.reshape(c, -1),
                          background=background.reshape(c, -1), jac_xy=jac.reshape(c, 2 * BINS, 2),
                          shape=(1, 2, BINS), repeats=repeats, meta={"synthetic": True})
