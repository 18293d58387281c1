"""``bench denali``: DENALI's benchmark protocol on captures simulated for a sensor, predicted beside real.

The captures are DENALI's protocol (:mod:`nlosplan.tasks.denali_protocol`) simulated by
:func:`nlosplan.data.build.build_dataset` for the sensor with the scene model its calibration comes with
(:func:`~nlosplan.simulators.presets.scene_model.scene_options`), build seed 0, default fidelity, into a
capture store that is reused: by default a content-keyed file under the cache folder
(``$NLOSPLAN_CACHE/denali-bench/KEY.sqlite``; the key holds the sensor, the scene options, the protocol, the
fidelity, the seed and a hash of the simulator's source, so a changed model simulates anew); an interrupted
build resumes. Each requested cell is then trained with DENALI's recipe
(:func:`~nlosplan.tasks.denali_recipe.train_denali_cell`) and shown beside DENALI's Table 1.

Budgets
-------
``full``
    DENALI's protocol: 30 objects x 2 sizes x 100 positions x lights on and off x 3 repeats = 36,000
    captures, DENALI's epochs (60-100). About two minutes per 1D CNN cell on a datacenter GPU, 8-14 min on 2
    idle CPU cores (measured 2026-11-29).
``quick``
    Every fifth gantry position (0, 5, ..., 95: 20 positions spread over the grid) = 7,200 captures, a
    fifth of DENALI's epochs (12 for localization, 20 for shape and size, 15 for the size MLP); DENALI's
    split of that subset. Not DENALI's numbers: a look at the trend in minutes (the output says so).

With ``validation`` (default on) each cell is trained a second time on its training rows minus a seeded
tenth to give an epoch chosen without the test set (:mod:`nlosplan.tasks.denali_recipe`); it doubles the
training time. With several ``seeds`` every recipe cell is trained once per seed of torch's generator (DENALI's
split stays its seed 42's): the spread of DENALI's figure over the draws of its own recipe, which one run cannot
show (:func:`seed_spread`).
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from nlosplan.denali import DENALI_OBJECTS, N_POSITIONS, SIZES
from nlosplan.errors import UserError
from nlosplan.tasks.denali_protocol import SEED

__all__ = ["BUDGETS", "BUILD_SEED", "QUICK_EPOCH_FRACTION", "QUICK_POSITION_STEP", "Protocol", "check_seeds",
           "checkpoint_check", "default_store", "estimate_seconds", "load_protocol_captures", "protocol_for",
           "run_denali_bench", "seed_spread"]

BUDGETS = ("full", "quick")
#: ``quick``: every n-th gantry position, and this fraction of DENALI's epochs (rounded up).
QUICK_POSITION_STEP = 5
QUICK_EPOCH_FRACTION = 0.2
#: Seed of the simulated captures' noise (``dataset build``'s default).
BUILD_SEED = 0
#: Source of the simulator whose edits make new store keys (relative to the package).
_CODE_PATHS = ("simulators", "sensor_models", "denali", "data/build.py", "constants.py", "_jax.py")


@dataclass(frozen=True)
class Protocol:
    """Which captures and how many epochs: DENALI's protocol, or a budget's subset of it.

    Attributes
    ----------
    budget : {"full", "quick", "custom"}
        ``custom``: objects, positions or epochs given by hand.
    objects, sizes, lights : tuple of str
    positions : tuple of int
    repeats : int
    epoch_fraction : float
        Share of each cell's DENALI epochs trained (rounded up), unless ``epochs`` is set.
    epochs : int or None
        Epochs for every cell.
    """

    budget: str
    objects: tuple
    sizes: tuple
    positions: tuple
    lights: tuple
    repeats: int
    epoch_fraction: float = 1.0
    epochs: int | None = None

    @property
    def n_captures(self) -> int:
        return len(self.objects) * len(self.sizes) * len(self.positions) * len(self.lights) * self.repeats

    def cell_epochs(self, denali_epochs: int) -> int:
        """Epochs of a cell whose DENALI count is ``denali_epochs``."""
        return self.epochs if self.epochs is not None else max(1, math.ceil(denali_epochs * self.epoch_fraction))

    def describe(self) -> str:
        """One line a person reads."""
        pos = (f"{len(self.positions)} positions" if self.positions != tuple(range(N_POSITIONS))
               else "all 100 positions")
        ep = (f"{self.epochs} epochs per cell" if self.epochs is not None else
              "DENALI's epochs" if self.epoch_fraction == 1 else f"{self.epoch_fraction:g} of DENALI's epochs")
        return (f"{self.n_captures:,} captures ({len(self.objects)} objects x {len(self.sizes)} sizes x {pos} x "
                f"lights {'/'.join(self.lights)} x {self.repeats} repeats), {ep}")


def protocol_for(budget: str, *, objects=None, positions=None, epochs: int | None = None) -> Protocol:
    """The protocol of a budget, optionally narrowed by hand (then ``budget="custom"``).

    Raises
    ------
    UserError
        An unknown budget, unknown objects, positions outside 0-99, ``epochs < 1``.
    """
    if budget not in BUDGETS:
        raise UserError(f"unknown --budget {budget!r}; allowed: {', '.join(BUDGETS)}")
    pos = tuple(range(0, N_POSITIONS, QUICK_POSITION_STEP)) if budget == "quick" else tuple(range(N_POSITIONS))
    frac = QUICK_EPOCH_FRACTION if budget == "quick" else 1.0
    objs = DENALI_OBJECTS
    if objects is not None:
        bad = [o for o in objects if o not in DENALI_OBJECTS]
        if bad or not objects:
            raise UserError(f"unknown object(s) {', '.join(bad) or '(none)'}; allowed: {', '.join(DENALI_OBJECTS)}")
        objs = tuple(dict.fromkeys(objects))
    if positions is not None:
        bad = [p for p in positions if not 0 <= int(p) < N_POSITIONS]
        if bad or not positions:
            raise UserError(f"positions {bad or '(none)'} not allowed; allowed: 0 to {N_POSITIONS - 1}")
        pos = tuple(sorted({int(p) for p in positions}))
    if epochs is not None and int(epochs) < 1:
        raise UserError(f"--epochs {epochs} must be >= 1")
    custom = objects is not None or positions is not None or epochs is not None
    return Protocol("custom" if custom else budget, tuple(objs), tuple(SIZES), pos, ("on", "off"), 3, frac,
                    None if epochs is None else int(epochs))


def _code_version() -> str:
    """SHA-256 (16 hex digits) of the simulator's source (:data:`_CODE_PATHS`)."""
    pkg = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for rel in _CODE_PATHS:
        p = pkg / rel
        for f in (sorted([*p.rglob("*.py"), *p.rglob("*.cc")]) if p.is_dir() else [p] if p.is_file() else []):
            h.update(str(f.relative_to(pkg)).encode())
            h.update(f.read_bytes())
    return h.hexdigest()[:16]


def _store_key(sensor, options: dict, protocol: Protocol, fidelity: str) -> str:
    doc = {"sensor": sensor.to_dict(), "scene_options": options, "objects": protocol.objects,
           "sizes": protocol.sizes, "positions": protocol.positions, "lights": protocol.lights,
           "repeats": protocol.repeats, "fidelity": fidelity, "seed": BUILD_SEED, "code": _code_version()}
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()[:24]


def default_store(sensor, options: dict, protocol: Protocol, fidelity: str = "default") -> Path:
    """``$NLOSPLAN_CACHE/denali-bench/KEY.sqlite`` (or under ``~/.cache/nlosplan``): the captures' store by content."""
    from nlosplan.resources import cache_root

    return cache_root() / "denali-bench" / f"{_store_key(sensor, options, protocol, fidelity)}.sqlite"


def load_protocol_captures(sensor_spec, protocol: Protocol, *, store=None, fidelity: str = "default",
                           progress=None) -> tuple[np.ndarray, "object", dict]:
    """Simulate (or reuse) a protocol's captures and return them in DENALI's order.

    Parameters
    ----------
    sensor_spec : str
        Preset name or sensor file; its calibrated scene model comes with it.
    protocol : Protocol
    store : path, optional
        Capture store to fill and read (default :func:`default_store`).
    fidelity : str
    progress : nlosplan.progress.Progress, optional

    Returns
    -------
    histograms : ndarray of float32, shape (N, rows, cols, bins)
    labels : pandas.DataFrame
        ``object``, ``size``, ``zones``, ``lights``, ``position``, ``repeat``, ``x``, ``y``, ... in DENALI's order.
    info : dict
        ``store``, ``sensor``, ``scene_options``, ``captures``, ``captures_added``, ``build_seconds``, ``variant``.
    """
    from nlosplan.data.build import build_dataset
    from nlosplan.data.store import CaptureStore
    from nlosplan.sensor_models import resolve_sensor
    from nlosplan.simulators.presets.scene_model import scene_model, scene_options, session_floor_sd
    from nlosplan.tasks.denali_protocol import capture_order

    sensor = resolve_sensor(sensor_spec)
    options = scene_options(scene_model(sensor_spec))
    sessions = session_floor_sd(scene_model(sensor_spec))
    path = Path(store) if store is not None else default_store(sensor, options, protocol, fidelity)
    path.parent.mkdir(parents=True, exist_ok=True)
    if progress is not None:
        progress.set_postfix_str("", refresh=False)
        progress.stage("simulating captures", protocol.n_captures, "capture")

    def built(done, total, text):
        if progress is not None:
            progress.set(done, total, text)

    with CaptureStore(path, synchronous="NORMAL") as st:
        res = build_dataset(st, sensor=sensor, objects=protocol.objects, sizes=protocol.sizes,
                            positions=protocol.positions, lights=protocol.lights, repeats=protocol.repeats,
                            fidelity=fidelity, seed=BUILD_SEED, scene_options=options, progress=built,
                            session_floor_sd=sessions)
        ds = st.load(source="sim:fast", sensor_hash=res["sensor_hash"], seed=BUILD_SEED, variant=res["variant"],
                     object=list(protocol.objects), size=list(protocol.sizes), position=list(protocol.positions),
                     lights=list(protocol.lights), repeat=list(range(protocol.repeats)))
    if len(ds) != protocol.n_captures:
        raise UserError(f"store {path} holds {len(ds)} of the protocol's {protocol.n_captures} captures after the "
                        "build; rerun to resume it")
    order = capture_order(ds.labels)
    info = {"store": str(path), "sensor": sensor.name, "scene_options": options, "captures": len(ds),
            "captures_added": res["captures_added"], "build_seconds": res["seconds"], "variant": res["variant"],
            "fidelity": fidelity, "build_seed": BUILD_SEED, "session_floor_sd": sessions}
    return ds.histograms[order], ds.labels.iloc[order].reset_index(drop=True), info


def estimate_seconds(models, tasks, protocol: Protocol, device: str, *, validation: bool, shape=(3, 3, 128),
                     n_seeds: int = 1) -> float:
    """Training time of the cells, from three timed training batches of each model on ``device`` now.

    ``n_seeds`` recipe runs per cell (:func:`run_denali_bench`'s ``seeds``); knn runs once.

    A rough figure for the warning before long work: evaluation passes count a third of a training pass.
    """
    import torch

    from nlosplan.tasks.denali_recipe import cell_settings, denali_model

    n_train = 0.7 * protocol.n_captures
    total = 0.0
    per_sample: dict[str, float] = {}
    if "knn" in models:  # distances of every test row to every training row, 3x3x128 counts: ~2e-7 s per pair here
        total += len(tasks) * 2e-7 * n_train * 0.3 * protocol.n_captures * (1 + 0.15 * len((1, 3, 5, 9, 15)))
        models = [m for m in models if m != "knn"]
    for model in models:
        net = denali_model(model, "shape", shape, 30).to(device)
        opt = torch.optim.Adam(net.parameters(), lr=1e-3)
        x = torch.rand((64,) + tuple(shape), device=device) * 100
        y = torch.zeros(64, dtype=torch.int64, device=device)
        times = []
        for _ in range(4):
            t0 = time.perf_counter()
            opt.zero_grad()
            torch.nn.functional.cross_entropy(net(x), y).backward()
            opt.step()
            if device.startswith("cuda"):
                torch.cuda.synchronize()
            times.append(time.perf_counter() - t0)
        per_sample[model] = min(times[1:]) / 64
    for model in models:
        for task in tasks:
            epochs = protocol.cell_epochs(cell_settings(model, task)["epochs"])
            runs = (2 if validation else 1) * n_seeds
            total += runs * epochs * per_sample[model] * (n_train + protocol.n_captures * 0.3 / 3)
    return total


def _row(res, real: float | None, val_res, protocol: Protocol, labels) -> dict:
    """One table row from a cell's result (and its validation run)."""
    from nlosplan.tasks.metrics import loc_rmse, top1_accuracy

    lights = labels["lights"].astype(str).to_numpy()[res.test_index]
    by_lights = {}
    for li in ("on", "off"):
        m = lights == li
        if not m.any():
            continue
        pred = res.predictions["best"][m]
        if res.task == "loc":
            truth = labels[["x", "y"]].to_numpy(dtype=np.float64)[res.test_index][m]
            by_lights[li] = loc_rmse(pred, truth)
        else:
            from nlosplan.tasks.denali_protocol import task_labels

            names = task_labels(labels.iloc[res.test_index[m]], res.task)
            truth = np.array([res.classes.index(v) for v in names])
            by_lights[li] = top1_accuracy(np.eye(len(res.classes))[pred], truth)
    return {"task": res.task, "model": res.model, "metric": res.metric, "predicted": res.predicted,
            "predicted_last_epoch": res.predicted_last_epoch,
            "predicted_validation_epoch": None if val_res is None else val_res.predicted_validation_epoch,
            "real": real, "budget": protocol.budget, "device": res.device, "seconds": res.seconds + (
                0.0 if val_res is None else val_res.seconds),
            "best_epoch": res.best_epoch, "epochs": res.epochs,
            "validation_epoch": None if val_res is None else val_res.validation_epoch,
            "n_train": res.n_train, "n_test": res.n_test, "n_train_validation_run": None if val_res is None
            else val_res.n_train, "predicted_by_lights": by_lights}


def check_seeds(seeds) -> tuple[int, ...]:
    """``seeds`` as distinct ints from 0 to :data:`~nlosplan.resources.MAX_SEED` (every seed the tool takes);
    UserError otherwise."""
    from nlosplan.resources import MAX_SEED

    out = []
    for v in seeds:
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not 0 <= int(v) <= MAX_SEED:
            raise UserError(f"seed {v!r} is not an integer from 0 to {MAX_SEED}")
        out.append(int(v))
    if not out or len(set(out)) != len(out):
        raise UserError(f"seeds {', '.join(map(str, out)) or '(none)'}: give one or more distinct seeds")
    return tuple(out)


def seed_spread(rows) -> list[dict]:
    """How DENALI's figure of each recipe cell spreads over the training seeds of one run.

    Parameters
    ----------
    rows : sequence of dict
        :func:`run_denali_bench`'s rows (knn's, with no seed, are left out).

    Returns
    -------
    list of dict
        Per task and model trained at two seeds or more: ``task``, ``model``, ``metric``, ``seeds``,
        ``predicted`` (best on test per seed, the metric's unit: metres or a fraction), ``mean``, ``sd`` (sample
        standard deviation over the seeds), ``min``, ``max``, ``predicted_last_epoch`` (per seed), ``real``
        (Table 1) and ``real_in_range`` (whether the real figure lies between the lowest and highest seed's).
    """
    groups: dict[tuple[str, str], list[dict]] = {}
    for r in rows:
        if r.get("seed") is not None:
            groups.setdefault((r["task"], r["model"]), []).append(r)
    out = []
    for (task, model), rs in groups.items():
        if len(rs) < 2:
            continue
        v = np.array([r["predicted"] for r in rs], dtype=np.float64)
        real = rs[0]["real"]
        out.append({"task": task, "model": model, "metric": rs[0]["metric"], "seeds": [r["seed"] for r in rs],
                    "predicted": v.tolist(), "mean": float(v.mean()), "sd": float(v.std(ddof=1)),
                    "min": float(v.min()), "max": float(v.max()),
                    "predicted_last_epoch": [r["predicted_last_epoch"] for r in rs], "real": real,
                    "real_in_range": None if real is None else bool(v.min() <= real <= v.max())})
    return out


def run_denali_bench(sensor_spec, *, budget: str = "quick", models=("cnn1d", "mlp"), tasks=("loc", "shape", "size"),
                     device: str = "cpu", validation: bool = True, store=None, objects=None, positions=None,
                     epochs: int | None = None, seeds=(SEED,), progress=None) -> dict:
    """DENALI's protocol on simulated captures of a sensor, each cell with DENALI's recipe, beside Table 1.

    Parameters
    ----------
    sensor_spec : str
        Preset name or sensor file.
    budget : {"full", "quick"}
        See the module notes.
    models : sequence of {"cnn1d", "mlp", "knn"}
        DENALI's recipe cells, and k nearest neighbours (:func:`~nlosplan.tasks.denali_knn.knn_cell`, not in
        Table 1: its ``real`` is None).
    tasks : sequence of {"loc", "shape", "size"}
    device : str
        A device of :func:`~nlosplan.tasks.denali_recipe.resolve_device` (resolved already or ``"auto"``).
    validation : bool
        Also train each cell on its training rows minus a seeded tenth (the validation-chosen epoch).
    store : path, optional
        Capture store (default: the content-keyed cache file).
    objects, positions, epochs : optional
        Narrow the protocol by hand (``budget`` becomes ``"custom"``).
    seeds : sequence of int
        Seeds of torch's generator (weights, batch order, dropout); each recipe cell is trained once per seed.
        Default DENALI's 42 alone. The split is DENALI's whatever the seeds; knn has no training seed and runs once.
    progress : nlosplan.progress.Progress, optional

    Returns
    -------
    dict
        ``rows`` (one per task and model: ``task``, ``model``, ``metric``, ``predicted`` (best-on-test, as
        DENALI), ``predicted_last_epoch``, ``predicted_validation_epoch``, ``real`` (Table 1), ``budget``,
        ``device``, ``seconds``, ``best_epoch``, ``epochs``, ``validation_epoch``, ``n_train``, ``n_test``,
        ``predicted_by_lights``, ``seed``: the training seed, None for knn), ``spread`` (with two seeds or more:
        :func:`seed_spread`), ``seeds``, ``cells`` (every run's :meth:`CellResult.to_dict`), ``protocol``,
        ``captures`` (where they came from), ``real_source``, ``device``, ``seconds``, ``torch_threads``.
    """
    import torch

    from nlosplan.tasks.denali_protocol import table1, task_labels
    from nlosplan.tasks.denali_recipe import RECIPE_MODELS, cell_settings, resolve_device, train_denali_cell
    from nlosplan.tasks.names import TASKS, check_names

    t0 = time.perf_counter()
    from nlosplan.tasks.denali_knn import KNN, knn_cell

    models = check_names("model(s)", models, RECIPE_MODELS + (KNN,))
    seeds = check_seeds(seeds)
    tasks = check_names("task(s)", tasks, TASKS)
    dev = resolve_device(device)
    protocol = protocol_for(budget, objects=objects, positions=positions, epochs=epochs)
    hist, labels, captures = load_protocol_captures(sensor_spec, protocol, store=store, progress=progress)
    real = table1()
    rows, cells = [], []
    for task in tasks:
        targets = task_labels(labels, task)
        if task != "loc" and len(set(targets)) < 2:
            raise UserError(f"task {task!r} needs at least 2 classes; the protocol has {', '.join(set(targets))}")
        for model in models:
            if model == KNN:   # no epochs: one test-blind fit, k chosen on a share of the training rows
                if progress is not None:
                    progress.stage(f"knn {task}", 1, "fit")
                res = knn_cell(hist, targets, task)
                if progress is not None:
                    progress.set(1, 1, f"k {res.settings['k']}, {res.settings['components']} components")
                rows.append({**_row(res, None, res, protocol, labels), "seed": None})   # test-blind already
                cells.append(res.to_dict())
                continue
            n_ep = protocol.cell_epochs(cell_settings(model, task)["epochs"])
            for seed in seeds:
                results = []
                for val in ([False, True] if validation else [False]):
                    if progress is not None:
                        progress.set_postfix_str("", refresh=False)
                        progress.stage(f"{model} {task}{' (validation run)' if val else ''}"
                                       f"{f' seed {seed}' if len(seeds) > 1 else ''}", n_ep, "epoch")
                        progress.set(0, n_ep)

                    def said(rec, p=progress, key="loc_rmse" if task == "loc" else "top1_acc"):
                        if p is not None:
                            p.set(rec["epoch"], rec["epochs"], f"test {key} {rec['test'][key]:.4g}")

                    results.append(train_denali_cell(hist, targets, task, model, epochs=n_ep, device=dev,
                                                     validation=val, seed=seed, progress=said))
                main_res, val_res = results[0], (results[1] if validation else None)
                ref = real["values"].get(task, {}).get(model, {}).get(main_res.metric)
                rows.append({**_row(main_res, ref, val_res, protocol, labels), "seed": int(seed)})
                cells += [r.to_dict() for r in results]
    return {"rows": rows, "spread": seed_spread(rows) if len(seeds) > 1 else [], "seeds": [int(v) for v in seeds],
            "cells": cells, "protocol": {**asdict(protocol), "captures": protocol.n_captures,
                                                        "description": protocol.describe()},
            "captures": captures, "real_source": real["source"], "device": dev, "validation": bool(validation),
            "seconds": time.perf_counter() - t0, "torch_threads": torch.get_num_threads(),
            "torch": torch.__version__}



def checkpoint_check(sensor_spec, checkpoints, *, budget: str = "quick", store=None, progress=None) -> dict:
    """DENALI's real-trained networks on captures simulated for a sensor: their scores and BatchNorm inputs.

    Parameters
    ----------
    sensor_spec : str
        Preset name or sensor file (3x3 zones, 128 bins: DENALI's networks take nothing else).
    checkpoints : sequence of DenaliCheckpoint
        From :func:`nlosplan.tasks.denali_checkpoints.load_checkpoint_dir`.
    budget : {"quick", "full"}
        ``full``: DENALI's protocol (36,000 captures), each network scored on the scenes of DENALI's real
        test split for its task (the same object, size, lighting, position and repeat as its real test
        score); ``quick``: the quick budget's 7,200 captures (every fifth position), each network scored on
        all of them (none was ever seen by it).
    store : path, optional
        Capture store (default: the content-keyed cache file; ``bench denali`` with the same budget shares it).
    progress : nlosplan.progress.Progress, optional

    Returns
    -------
    dict
        ``checkpoints`` (:func:`~nlosplan.tasks.denali_checkpoints.evaluate_checkpoints`), ``rows_scored``
        (which captures), ``protocol``, ``captures``, ``seconds``.
    """
    from nlosplan.sensor_models import resolve_sensor
    from nlosplan.tasks.denali_checkpoints import evaluate_checkpoints
    from nlosplan.tasks.denali_protocol import denali_split, task_labels

    t0 = time.perf_counter()
    sensor = resolve_sensor(sensor_spec)
    if (sensor.zones_rows, sensor.zones_cols, sensor.n_bins) != (3, 3, 128):
        raise UserError(f"DENALI's networks take 3x3 zones and 128 bins; sensor {sensor.name} has "
                        f"{sensor.zones_rows}x{sensor.zones_cols} zones and {sensor.n_bins} bins")
    protocol = protocol_for(budget)
    hist, labels, captures = load_protocol_captures(sensor_spec, protocol, store=store, progress=progress)
    rows = None
    if budget == "full":
        rows = {t: denali_split(t, task_labels(labels, t))[1] for t in {c.task for c in checkpoints}}
    step = None
    if progress is not None:
        progress.stage("running DENALI's networks", len(checkpoints), "network")
        step = lambda name: progress.update(1, text=name)  # noqa: E731
    res = evaluate_checkpoints(checkpoints, hist, labels, rows=rows, on_done=step)
    return {"checkpoints": res, "rows_scored": "the scenes of DENALI's real test split" if rows else
            "all simulated captures", "protocol": {**asdict(protocol), "captures": protocol.n_captures,
                                                   "description": protocol.describe()},
            "captures": captures, "seconds": time.perf_counter() - t0}
