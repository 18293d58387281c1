"""The training budget of the design's learners: how many training captures each trained evaluation gets.

A verdict is about a sensor *and* a learner with a training budget ("met with a 1D CNN trained on 2,100
captures"), so the budget is an input of the run: the trained evaluator's knob ``train_captures``
(``[search.fidelity.trained]``, ``nlosplan design --train-captures N``). It is part of every trained job's knobs,
hence of the evaluation's key (what resume looks up) and of the run's configuration hash (a resume with another
budget is refused).

A *training capture* is one training row of the learner: a histogram of a training scene, the mean of the
evaluator's ``repeats`` noisy captures (simulated), or one real capture (``--real``). The split is DENALI's
70/30 by scene; the learner holds out 15 % of its training captures for early stopping (as a count, they are
training captures: DENALI's 25,200 are its whole training side).

- **Default** (``train_captures`` not given): one capture per training scene of the evaluation's scene set, as
  the evaluator always did (:func:`default_captures`: 2,100 for the main job's 3,000 scenes, 700 for
  ``--quick``; the worlds' learners, on every ``scene_step``-th position, that many fewer; with ``--real``, every
  real capture of the training scenes).
- **N below that**: a seeded subset of the training captures, stratified on the class where every class allows
  it (the test scenes stay the same).
- **N above it** (simulated only): more noisy captures of the training scenes are drawn, each from its own noise
  stream, spread evenly over the scenes (:func:`training_set`). Real captures cannot be drawn again: a run with
  ``--real`` refuses an N above what the store's training side holds before any work (:func:`check_real_budget`).

Every trained evaluation records ``train_captures`` (asked; None: the default), ``n_train`` (training captures
it really had: equal to the asked N unless ``train_note`` says why not), ``n_fit`` and ``n_val`` in its ``extra``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from nlosplan.errors import UserError
from nlosplan.resources import MAX_TRAIN_CAPTURES

__all__ = ["TRAIN_CAPTURES", "TRAIN_NOTE", "MAX_TRAIN_CAPTURES", "MIN_TRAIN_CAPTURES", "requested",
           "check_captures_value", "training_scenes", "default_captures", "check_budget_memory", "Capacity",
           "real_capacity", "check_real_budget", "training_set", "budget_statement", "TEST_SIZE"]

#: The trained evaluator's knob (``[search.fidelity.trained] train_captures``).
TRAIN_CAPTURES = "train_captures"
#: Where an evaluation's ``extra`` says why it had fewer training captures than asked.
TRAIN_NOTE = "train_note"
#: The test side of the trained evaluator's random split by scene (DENALI's).
TEST_SIZE = 0.3
#: Fewest training captures a learner can be given (one to fit, one more to have a set).
MIN_TRAIN_CAPTURES = 2


def check_captures_value(n, where: str = "train_captures") -> int:
    """``n`` as a training budget: a whole number from 2 to :data:`MAX_TRAIN_CAPTURES` (UserError, one line)."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not \
            MIN_TRAIN_CAPTURES <= int(n) <= MAX_TRAIN_CAPTURES:
        raise UserError(f"{where}={n!r} must be a whole number of training captures from {MIN_TRAIN_CAPTURES} to "
                        f"{MAX_TRAIN_CAPTURES:,}")
    return int(n)


def requested(fidelity: dict) -> int | None:
    """The training captures a trained job's knobs ask for (None: the default, one per training scene)."""
    n = fidelity.get(TRAIN_CAPTURES)
    return None if n is None else check_captures_value(n)


def training_scenes(n_scenes: int) -> int:
    """Scenes the 70/30 random split leaves for training (scikit-learn's count: the test side is ``ceil(0.3 n)``)."""
    from nlosplan.tasks.splits import random_split

    return int(len(random_split(int(n_scenes), test_size=TEST_SIZE).train)) if n_scenes >= 2 else 0


def default_captures(n_scenes: int) -> int:
    """The default budget of a simulated scene set of ``n_scenes`` scenes: one capture per training scene."""
    return training_scenes(n_scenes)


class Capacity(NamedTuple):
    """What a real store's training side holds.

    Attributes
    ----------
    captures : int
        Training captures: those of the split's training scenes (exact where every scene has as many repeats;
        else the most any split can hold).
    scenes : int
        Training scenes (70 % of the scenes).
    total : int
        Captures in all.
    """

    captures: int
    scenes: int
    total: int


def real_capacity(labels) -> Capacity:
    """What the captures of ``labels`` hold for training (backgrounds dropped; a scene's repeats share its key)."""
    from nlosplan.data.dataset import scene_keys

    per_scene = np.sort(scene_keys(labels).value_counts().to_numpy())[::-1]
    m = training_scenes(len(per_scene))
    return Capacity(int(per_scene[:m].sum()), m, int(per_scene.sum()))


def check_real_budget(n: int | None, store, where: dict) -> Capacity | None:
    """Refuse (one line, before any work) a budget above the training captures a real store holds.

    Parameters
    ----------
    n : int or None
        The asked budget (None: every training capture; nothing to check).
    store : str
        The capture store (already checked to hold matching captures).
    where : dict
        The label filter of the run's real captures.

    Returns
    -------
    Capacity or None
        :func:`real_capacity` of the store's captures (None when ``n`` is None).
    """
    if n is None:
        return None
    from nlosplan.data.store import CaptureStore

    with CaptureStore(store, readonly=True) as st:
        labels = st.labels(**where)
    cap = real_capacity(labels[labels.class_group.astype(str) != "background"])
    if n > cap.captures:
        raise UserError(f"train_captures={n:,} (--train-captures) is more than the {cap.captures:,} training captures "
                        f"in {store} (its {cap.total:,} captures; the 70 % training side holds {cap.scenes:,} of their "
                        f"scenes; real captures cannot be drawn again): give at most {cap.captures:,}")
    return cap


#: Bytes per histogram cell of one training capture while a learner's set is drawn and trained (float64 mean and
#: int64 Poisson draw, the float32 set and its torch copy): an estimate, not a measured peak.
BYTES_PER_CELL = 24


def check_budget_memory(n: int | None, cells: int, workers: int) -> None:
    """Refuse (one line, before any work) a budget whose training sets cannot be held by ``workers`` at once.

    Parameters
    ----------
    n : int or None
        The asked budget (None: the default; nothing to check).
    cells : int
        Histogram cells of the largest zone layout (rows x cols x bins).
    workers : int
        Evaluations that run at once.
    """
    if n is None:
        return
    from nlosplan.resources import check_memory

    check_memory(float(n) * cells * BYTES_PER_CELL * workers, f"--train-captures {n:,} on {workers} worker(s)",
                 "give a smaller N or fewer --workers")


def _subset(y, have: int, n: int, seed: int, stratify: bool) -> np.ndarray:
    """``n`` of ``have`` training rows, seeded; stratified on ``y`` where every class allows it."""
    from sklearn.model_selection import train_test_split

    idx = np.arange(have)
    strat = None
    if stratify:
        _, counts = np.unique(y, return_counts=True)
        if counts.min() >= 2 and n >= len(counts) and have - n >= len(counts):
            strat = y
    keep, _ = train_test_split(idx, train_size=n, stratify=strat, random_state=int(seed) % 2**32)
    return np.sort(keep)


def training_set(x: np.ndarray, y: np.ndarray, n: int | None, *, seed: int, stratify: bool,
                 more=None) -> tuple[np.ndarray, np.ndarray, str]:
    """The learner's training captures at a budget of ``n``.

    Parameters
    ----------
    x : ndarray, shape (M, R, C, B)
        The split's training captures (one per training scene, simulated; every capture of the training
        scenes, real).
    y : ndarray, shape (M, 2) or (M,)
        Their targets (x, y in metres, or class names).
    n : int or None
        The budget (None: ``x`` as it is).
    seed : int
        The evaluation's seed (the subset and which scenes are drawn again).
    stratify : bool
        Keep the classes' shares in a subset (classification).
    more : callable, optional
        ``more(rows) -> ndarray (len(rows), R, C, B)``: a fresh noisy capture of each listed training row (rows
        may repeat; simulated references); None where captures cannot be drawn again (real).

    Returns
    -------
    x, y, note
        ``n`` training captures (fewer only where ``more`` is None: then ``note`` says why; else empty).
    """
    have = len(x)
    if n is None or n == have:
        return x, y, ""
    if n < have:
        keep = _subset(y, have, n, seed, stratify)
        return x[keep], y[keep], ""
    if more is None:
        return x, y, (f"the training split holds {have:,} real captures, fewer than the {n:,} asked (real captures "
                      "cannot be drawn again)")
    full, rest = divmod(n - have, have)  # every training scene drawn again `full` times, `rest` of them once more
    rng = np.random.default_rng([int(seed), 11])
    rows = np.concatenate([np.tile(np.arange(have), full), np.sort(rng.choice(have, rest, replace=False))])
    x_more = np.asarray(more(rows), dtype=x.dtype)
    if x_more.shape != (len(rows),) + x.shape[1:]:
        raise RuntimeError(f"drawn captures are {x_more.shape}, expected {(len(rows),) + x.shape[1:]}")
    return np.concatenate([x, x_more]), np.concatenate([y, y[rows]]), ""


def budget_statement(n: int | None, *, default: int, learners: dict, models, epochs: int, repeats: int,
                     real: bool = False) -> dict:
    """The run's ``train_captures`` entry of ``result.json``: the budget asked and the learner family.

    Parameters
    ----------
    n : int or None
        The asked budget (None: the default).
    default : int
        The default's value at the reference design (one capture per training scene; with ``--real`` the
        training captures of the store).
    learners : dict
        Task name -> the chosen learner.
    models : sequence of str
        The candidate learners.
    epochs : int
        The trained evaluator's epoch cap.
    repeats : int
        Noisy captures averaged into one simulated training capture.
    real : bool
        The trained evaluator reads real captures.

    Returns
    -------
    dict
        ``requested`` (the budget, the default's value where none was asked), ``default`` (whether it is the
        default), ``rule`` (one line), ``learner`` (task -> learner), ``models``, ``epochs``, ``captures``
        (``simulated`` or ``real``).
    """
    what = "real captures" if real else f"each the mean of {repeats} noisy captures of its scene"
    if n is None:
        rule = "the default: one per training scene, 70 % of the scenes"
    elif n < default:
        rule = f"--train-captures {n:,}: a seeded subset of the {default:,} of one per training scene"
    elif n == default:
        rule = f"--train-captures {n:,}: one per training scene"
    else:
        rule = f"--train-captures {n:,}: one per training scene ({default:,}) and {n - default:,} more noisy ones drawn"
    rule = f"{rule}; {what}"
    return {"requested": default if n is None else n, "default": n is None, "rule": rule, "learner": dict(learners),
            "models": list(models), "epochs": int(epochs), "captures": "real" if real else "simulated"}
