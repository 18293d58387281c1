"""Small synthetic datasets whose labels can be learnt from the histograms (for the task-room tests).

Every scene has, per zone, a pulse whose bin moves with x (the same in all
zones) and whose spread across zone columns/rows grows with y, so both
absolute and relative timing carry the position; the object class adds a
second pulse at a class-specific zone and delay, and the size scales the
object pulses (8 in twice as bright as 4 in). Noise is Poisson.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from nlosplan.data.dataset import Dataset

#: Two objects from each DENALI class group.
OBJECTS = ("1", "7", "A", "S", "circle", "plus")
GROUPS = {"1": "numbers", "7": "numbers", "A": "letters", "S": "letters", "circle": "shapes", "plus": "shapes"}
X_RANGE = (0.969, 1.308)  # DENALI's gantry span, metres
Y_RANGE = (0.166, 0.508)


def grid_xy(n_side: int) -> np.ndarray:
    """(n_side**2, 2) positions on a grid over DENALI's span, position index = row number."""
    xs, ys = np.linspace(*X_RANGE, n_side), np.linspace(*Y_RANGE, n_side)
    return np.array([(x, y) for y in ys for x in xs])


def _pulse(bins: int, centre: float, width: float = 1.2) -> np.ndarray:
    t = np.arange(bins)
    return np.exp(-0.5 * ((t - centre) / width) ** 2)


def synthetic_dataset(*, objects=OBJECTS, sizes=("4in", "8in"), n_side: int = 6, repeats: int = 1,
                      bins: int = 32, zones=(3, 3), seed: int = 0, amplitude: float = 200.0) -> Dataset:
    """A learnable dataset of ``len(objects) * len(sizes) * n_side**2 * repeats`` rows, (rows, cols, bins)."""
    rng = np.random.default_rng(seed)
    rows, cols = zones
    xy = grid_xy(n_side)
    hists, labels = [], []
    for oi, obj in enumerate(objects):
        for size in sizes:
            gain = 2.0 if size == "8in" else 1.0
            for p, (x, y) in enumerate(xy):
                xn = (x - X_RANGE[0]) / (X_RANGE[1] - X_RANGE[0])
                yn = (y - Y_RANGE[0]) / (Y_RANGE[1] - Y_RANGE[0])
                mean = np.full((rows, cols, bins), 5.0)
                mean[..., 1] += 2000.0  # the wall's direct peak
                for r in range(rows):
                    for c in range(cols):
                        centre = 6 + 10 * xn + 3 * yn * (c - (cols - 1) / 2) + 2 * yn * (r - (rows - 1) / 2)
                        mean[r, c] += amplitude * gain * _pulse(bins, centre)
                zr, zc = divmod(oi % (rows * cols), cols)
                mean[zr, zc] += amplitude * gain * _pulse(bins, bins - 8 + (oi % 4) * 1.5, 0.8)
                for rep in range(repeats):
                    hists.append(rng.poisson(mean).astype(np.float32))
                    labels.append({"object": obj, "size": size, "class_group": GROUPS.get(obj, "shapes"),
                                   "position": p, "x": float(x), "y": float(y), "lights": "off",
                                   "zones": f"{rows}x{cols}", "repeat": rep, "source": "sim:synthetic"})
    return Dataset(np.stack(hists), pd.DataFrame(labels), 92.82)


def random_dataset(n_objects: int = 30, n_positions: int = 100, sizes=("4in", "8in"), bins: int = 128,
                   seed: int = 0) -> Dataset:
    """Random counts of DENALI's shape, (objects x sizes x positions, 3, 3, bins), for timing."""
    from nlosplan.denali import DENALI_OBJECTS, class_group, positions_xy

    rng = np.random.default_rng(seed)
    xy = positions_xy()
    labels = [{"object": o, "size": s, "class_group": class_group(o), "position": p, "x": float(xy[p, 0]),
               "y": float(xy[p, 1]), "lights": "off", "zones": "3x3", "repeat": -1, "source": "random"}
              for o in DENALI_OBJECTS[:n_objects] for s in sizes for p in range(n_positions)]
    hist = rng.poisson(50.0, size=(len(labels), 3, 3, bins)).astype(np.float32)
    return Dataset(hist, pd.DataFrame(labels), 92.82)
