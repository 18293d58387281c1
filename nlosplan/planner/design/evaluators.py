"""Evaluate one design on one task: fast bounds (screen) and trained models (verification).

An evaluation is a typed job in and a plain dict out (:func:`evaluate`), so
it runs the same in this process, a local process pool or on Dask workers;
the dict is the line the run logs, typed by the search when it ingests it
(:class:`~nlosplan.planner.design.evaluation.Evaluation`).
Every result records the design, task, evaluator, fidelity, seed, metric
value with its interval, run time and status (``ok``, ``unreachable`` with
the reason, or ``failed`` with the error).

Evaluators
----------
``bound``
    Localization: the Cramér–Rao bound on (x, y) with the photon scale a
    nuisance, on DENALI's ``loc_rmse`` (the trace of the position covariance
    is a 2-D mean square, so it is halved under the root), RMS over the bound
    scenes (from the simulated reference's Jacobian, degraded to the design;
    no interval: it is exact for those scenes). Shape and size: the ideal observer's Monte-Carlo accuracy
    (Poisson likelihood under every hypothesis, position and the other
    label unknown), Wilson interval; with ``fidelity["stop_at"]`` (the search
    passes its requirements' thresholds of the task) the captures are drawn
    in ``looks`` rounds and stop once the accuracy's 99.9 % interval is clear
    of every threshold (``extra["draws"]``: per class drawn). A bound is
    optimistic: a design that fails it fails every model.
``trained``
    A benchmark model (``fidelity["model"]``: the run's best learner of the
    task) trained on noisy captures of the design (repeats averaged), random
    70/30 split by scene, metric on the test scenes; interval by bootstrap
    over the test scenes. ``fidelity["train_captures"]`` (the training
    budget, :mod:`~nlosplan.planner.design.budget`) sets how many training
    captures the learner gets: a subset of one per training scene, or more
    noisy captures of them drawn; without it, one per training scene. The
    seed draws the Poisson noise, the split and the training (a re-run at
    another seed changes all three). The split,
    targets, training settings and training are the benchmark's
    (:func:`~nlosplan.tasks.benchmark.task_data`,
    :func:`~nlosplan.tasks.benchmark.train_config`,
    :func:`~nlosplan.tasks.training.train_model`), the metrics the scoring
    module's (:mod:`nlosplan.tasks.metrics`: ``loc_rmse``, ``top1_acc``;
    ``loc_rms_distance`` in ``extra``): :func:`trained_metric` gives the
    benchmark table's number for the same model and data.
"""

from __future__ import annotations

import math
import time

import numpy as np

from nlosplan.planner.design.budget import TRAIN_CAPTURES, TRAIN_NOTE, requested, training_set
from nlosplan.planner.design.data import load_reference
from nlosplan.planner.design.evaluation import Evaluator, Status
from nlosplan.planner.design.jobs import DesignJob
from nlosplan.planner.design.requirements import METRIC_OF_TASK, Condition, Task
from nlosplan.planner.design.worlds import world_sensor
from nlosplan.sensor_models.noise import CaptureNoise

__all__ = ["evaluate", "trained_metric", "DEFAULT_FIDELITY"]

#: Knobs of each evaluator (the error-against-run-time axis of the report). The trained evaluator's
#: ``model`` is set per task by the search (the run's best learner); "mlp" where none is chosen.
DEFAULT_FIDELITY: dict[str, dict] = {
    "bound": {"draws": 400, "looks": 8, "crlb_repeats": 1},
    "trained": {"model": "mlp", "epochs": 30, "width": 0.25, "repeats": 2, "bootstrap": 200},
}


def _rows(labels, condition: Condition | None) -> np.ndarray:
    return np.ones(len(labels), bool) if condition is None else condition.mask(labels)


def _crlb(ref, deg, repeats: int, condition) -> tuple[float, str]:
    from nlosplan.tasks.fisher import analyse_fisher, poisson_fisher

    lam, jac = ref.design_crlb(deg)
    keep = _rows(ref.crlb_labels, condition) if ref.crlb_labels is not None else np.ones(len(lam), bool)
    lam, jac = lam[keep], jac[keep]
    n, p = lam.shape[0], jac.shape[-1]
    names = ("x", "y") + tuple(f"p{i}" for i in range(p - 2))
    traces, bad = [], []
    for i in range(n):
        f = poisson_fisher(lam[i].reshape(-1), jac[i].reshape(-1, p), repeats)
        res = analyse_fisher(f, names)
        tr = float(np.trace(res["covariance"])) if res["position_identifiable"] else math.inf
        traces.append(tr)
        if not math.isfinite(tr):
            bad.append(res["reason"] or "zero information")
    # the trace is the 2-D mean square (var_x + var_y); loc_rmse pools x and y: halve it under the root
    value = math.sqrt(float(np.mean(traces)) / 2.0) if traces else math.nan
    return value, (f"{len(bad)} of {n} scenes not identifiable: {bad[0]}" if bad else "")


def _observer(ref, deg, task: str, fid: dict, seed: int, condition) -> tuple[float, tuple[float, float], dict]:
    from nlosplan.tasks.ideal_observer import observer_accuracy

    # the observer knows this world's capture sessions, as the learners' training captures of the same seed carry
    # them (without them a learner that reads a session's floor would beat its "ideal" observer)
    means = ref.design_means(deg, session_seed=seed)
    lab = ref.labels
    keep = _rows(lab, condition)
    objects = list(dict.fromkeys(lab["object"]))
    sizes = list(dict.fromkeys(lab["size"]))
    positions = list(dict.fromkeys(lab["position"]))
    idx = {(o, s, p): i for i, (o, s, p) in enumerate(zip(lab["object"], lab["size"], lab["position"]))}
    hyps = [(o, s) for o in objects for s in sizes
            if any(keep[idx[(o, s, p)]] for p in positions if (o, s, p) in idx)]
    cube = np.stack([np.stack([means[idx[(o, s, p)]].reshape(-1) for p in positions]) for o, s in hyps])
    if task == Task.SHAPE:
        classes = sorted({o for o, _ in hyps})
        class_of = [classes.index(o) for o, _ in hyps]
    else:
        classes = sorted({s for _, s in hyps})
        class_of = [classes.index(s) for _, s in hyps]
    if len(classes) < 2:
        return math.nan, (math.nan, math.nan), {}
    res = observer_accuracy(cube, np.asarray(class_of), draws=int(fid["draws"]), seed=seed,
                            capture_noise=CaptureNoise.of(ref.sensor),
                            stop_at=fid.get("stop_at") or None, looks=int(fid.get("looks", 1)))
    return (float(res["accuracy"]), tuple(float(v) for v in res["ci"]),
            {"draws": res["draws"], "stopped_early": res["stopped_early"]})


def _bootstrap(values_fn, n: int, draws: int, seed: int) -> tuple[float, float]:
    rng = np.random.default_rng(seed)
    stats = [values_fn(rng.integers(0, n, n)) for _ in range(draws)]
    return float(np.percentile(stats, 2.5)), float(np.percentile(stats, 97.5))


def _trained(ref, deg, task: str, fid: dict, seed: int, condition) -> tuple[float, tuple[float, float], dict]:
    import torch

    from nlosplan.data.dataset import Dataset

    torch.set_num_threads(1)
    # repeats averaged, as DENALI does (drawn as one Poisson sum: the same law at a 1 / repeats of the draws)
    # the capture sessions' floors are drawn from the seed (every repeat and position of a session shares one)
    hist = ref.design_mean_capture(deg, np.random.default_rng([seed, 7]), int(fid["repeats"]),
                                   session_seed=seed).astype(np.float32)
    labels = ref.labels.copy()
    labels["zones"] = f"{hist.shape[1]}x{hist.shape[2]}"
    labels["repeat"] = -1
    labels["source"] = ref.source
    more = None
    if not ref.is_counts:  # more noisy captures of training scenes, each from its own stream (a budget above one each)
        extra_rng = np.random.default_rng([seed, 8])
        more = lambda rows: ref.design_mean_capture(deg, extra_rng, int(fid["repeats"]), rows=rows,  # noqa: E731
                                                    session_seed=seed)
    return trained_metric(Dataset(hist, labels, deg.bin_width_ps), task, fid, seed, condition, more=more)


def trained_metric(ds, task: str, fid: dict, seed: int, condition: Condition | None = None, *, more=None
                   ) -> tuple[float, tuple[float, float], dict]:
    """Train ``fid["model"]`` on ``ds`` as the benchmark does and score the test rows.

    Parameters
    ----------
    ds : nlosplan.data.dataset.Dataset
        One row per scene (repeats already averaged).
    task : {"loc", "shape", "size"}
    fid : dict
        ``model``, ``epochs``, ``width``, ``bootstrap`` (draws of the interval); ``train_captures`` (optional:
        the training budget, :mod:`~nlosplan.planner.design.budget`).
    seed : int
        Seed of the split and the training (:func:`~nlosplan.tasks.benchmark.run_benchmark`'s ``seed``).
    condition : Condition, optional
        The test rows the metric is computed on.
    more : callable, optional
        ``more(rows)``: fresh noisy captures of rows of ``ds`` (a budget above one capture per training scene
        draws them; see :func:`~nlosplan.planner.design.budget.training_set`).

    Returns
    -------
    value, (lo, hi), extra
        ``loc_rmse`` (m) or ``top1_acc`` on the test rows, its bootstrap 95 % interval, and details
        (``epochs``, ``train_captures`` (asked; None: the default), ``n_train`` (training captures, the
        learner's early-stopping share included), ``n_fit``, ``n_val``, ``n_test``, ``train_seconds``;
        ``train_note`` where ``n_train`` is less than asked; ``loc_rms_distance`` for localization). Without
        ``train_captures`` the value equals the benchmark table's overall ``loc_rmse`` / ``top1_acc`` of the
        same model, data, seed, epochs and width.
    """
    from nlosplan.tasks.benchmark import task_classes, task_data, train_config
    from nlosplan.tasks.metrics import loc_rms_distance, loc_rmse, top1_accuracy
    from nlosplan.tasks.training import train_model

    classes = task_classes(ds, task)
    data = task_data(ds, task, "random", seed=seed, classes=classes)
    asked = requested(fid)
    x, y, note = training_set(data.train.histograms, data.y_train, asked, seed=seed, stratify=task != Task.LOC,
                              more=None if more is None else (lambda rows: more(data.split.train[rows])))
    if fid["model"] == "knn":   # no epochs, no width: components and k are chosen on the same validation share
        from nlosplan.tasks.neighbours import fit_neighbours

        model = fit_neighbours(x, y, task=task, classes=classes, seed=seed)
    else:
        cfg = train_config(fid["model"], task, epochs=int(fid["epochs"]), seed=seed)
        model = train_model(x, y, model=fid["model"], task=task, config=cfg, width=float(fid["width"]),
                            classes=classes)
    keep = _rows(data.test.labels, condition)
    scores, truth = model.predict(data.test.histograms)[keep], data.y_test[keep]
    score = loc_rmse if task == Task.LOC else top1_accuracy
    stat = lambda i: score(scores[i], truth[i])  # noqa: E731
    n = int(keep.sum())
    if n == 0:
        return math.nan, (math.nan, math.nan), {}
    value = stat(np.arange(n))
    lo, hi = _bootstrap(stat, n, int(fid["bootstrap"]), seed)
    knn = fid["model"] == "knn"
    extra = {"model": fid["model"], "epochs": 0 if knn else len(model.history), TRAIN_CAPTURES: asked,
             "n_train": len(x), "n_fit": int(model.n_train), "n_val": int(model.n_val), "n_test": n,
             "train_seconds": float(model.train_seconds)}
    if knn:
        extra["k"], extra["components"] = int(model.k), int(model.components)
    if note:
        extra[TRAIN_NOTE] = note
    if task == Task.LOC:
        extra["loc_rms_distance"] = loc_rms_distance(scores, truth)
    return value, (lo, hi), extra


def evaluate(job: DesignJob) -> dict:
    """Run one evaluation.

    Parameters
    ----------
    job : DesignJob
        ``evaluator`` (``"bound"``, ``"trained"``, or ``"trained_sim"``: trained on
        simulated captures when ``trained`` reads real ones), ``task``, ``design``,
        ``seed``, ``fidelity`` (dict of knobs), ``condition`` (a :class:`Condition`
        or None), ``reference`` (path of the saved
        :class:`~nlosplan.planner.design.data.ReferenceData` of the design's zone
        layout, a world's in a world), ``reference_sensor`` (the space's reference,
        a dict) and ``world`` (the world's sensor overrides, or None).

    Returns
    -------
    dict
        The job's fields (:meth:`DesignJob.to_dict`, with ``key``) plus ``metric``,
        ``value``, ``lo``, ``hi``, ``seconds``, ``status`` and ``reason``, and
        ``extra`` details.
    """
    from nlosplan.sensor_models import SensorConfig

    t0 = time.perf_counter()
    out = {**job.to_dict(), "metric": METRIC_OF_TASK[job.task][0], "value": math.nan, "lo": math.nan,
           "hi": math.nan, "status": Status.OK, "reason": "", "extra": {}}
    try:
        ref = load_reference(job.reference)
        deg, why = ref.degradation(world_sensor(job.design, SensorConfig.from_dict(job.reference_sensor), job.world))
        if deg is None:
            out.update(status=Status.UNREACHABLE, reason=why)
        elif job.evaluator is Evaluator.BOUND and job.task is Task.LOC:
            value, note = _crlb(ref, deg, int(job.fidelity.get("crlb_repeats", 1)), job.condition)
            out.update(value=value, lo=value, hi=value, reason=note)
        elif job.evaluator is Evaluator.BOUND:
            value, (lo, hi), extra = _observer(ref, deg, job.task.value, job.fidelity, int(job.seed), job.condition)
            out.update(value=value, lo=lo, hi=hi, extra=extra)
        else:
            value, (lo, hi), extra = _trained(ref, deg, job.task.value, job.fidelity, int(job.seed), job.condition)
            out.update(value=value, lo=lo, hi=hi, extra=extra)
    except Exception as exc:  # recorded, never fatal to the search
        out.update(status=Status.FAILED, reason=f"{type(exc).__name__}: {exc}")
    out["seconds"] = time.perf_counter() - t0
    return out
