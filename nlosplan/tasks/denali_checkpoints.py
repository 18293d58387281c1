"""DENALI's networks trained on real captures: loaded safely, run on (simulated) captures, their BatchNorm inputs.

DENALI ships its trained cells (``benchmark/main_table/checkpoints``, github.com/NikhilBehari/denali, MIT).
Four of them are read here, by file name:

==============  =====  ======  =========================================================  ================
file            task   model   input                                                      real test score
==============  =====  ======  =========================================================  ================
reg_1dcnn.pth   loc    cnn1d   raw counts                                                 sqrt(test_mse)
obj_1dcnn.pth   shape  cnn1d   raw counts                                                 test top-1
size_1dcnn.pth  size   cnn1d   raw counts                                                 test top-1
obj_mlp.pth     shape  mlp     log1p(clip(x, 0)) z-scored with the evaluated set's own    test top-1
                               mean and standard deviation (DENALI's file keeps none)
==============  =====  ======  =========================================================  ================

Safety: the files are pickles. They are read with ``torch.load(weights_only=True)`` and an explicit
allow-list of numpy's array-rebuilding functions under the numpy-1 names the files use
(:func:`allowed_globals`); a file that needs anything else is refused with one line naming it and is never
unpickled. A file that loads but is not the DENALI network its name says (an nlosplan checkpoint, another
state dict) is refused too: its weights must fit DENALI's architecture with ``strict=True``.

BatchNorm statistics (:func:`bn_input_statistics`): each BatchNorm layer of the 1D CNNs keeps the running
mean and variance of its input over DENALI's real training captures. For the evaluated captures the same
moments are taken per channel over batch and time (as ``BatchNorm1d`` computes them, in eval mode, i.e.
through the upstream layers as the network runs at inference), and compared:
``z = (mean - running_mean) / sqrt(running_var)`` and ``log(var / running_var)``.
"""

from __future__ import annotations

import pickle
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from nlosplan.errors import UserError
from nlosplan.tasks.denali_protocol import DENALI_CLASSES, DENALI_SIZE_NAMES, task_labels
from nlosplan.tasks.denali_recipe import denali_model
from nlosplan.tasks.metrics import loc_rmse, top1_accuracy

__all__ = ["CHECKPOINTS", "DenaliCheckpoint", "allowed_globals", "bn_input_statistics", "evaluate_checkpoints",
           "load_checkpoint_dir", "load_denali_checkpoint", "read_checkpoint_payload"]

#: DENALI's file name -> (task, model), in the order reported.
CHECKPOINTS: dict[str, tuple[str, str]] = {"reg_1dcnn": ("loc", "cnn1d"), "obj_1dcnn": ("shape", "cnn1d"),
                                           "size_1dcnn": ("size", "cnn1d"), "obj_mlp": ("shape", "mlp")}
_CLASSES = {"shape": DENALI_CLASSES, "size": tuple(sorted(DENALI_SIZE_NAMES.values()))}
_INPUT_SHAPE = (3, 3, 128)


def allowed_globals() -> list:
    """numpy's array-rebuilding functions and dtype classes, under the numpy-1 names DENALI's files use.

    The only Python objects :func:`read_checkpoint_payload` lets ``torch.load`` rebuild besides torch's own
    tensors and plain containers.
    """
    core = np._core.multiarray  # numpy 2's home of the functions the files call numpy.core.multiarray.*
    out: list = [(core._reconstruct, "numpy.core.multiarray._reconstruct"),
                 (core.scalar, "numpy.core.multiarray.scalar"), np.ndarray, (np.dtype, "numpy.dtype")]
    out += [getattr(np.dtypes, name) for name in np.dtypes.__all__]
    return out


_GLOBAL = re.compile(r"GLOBAL ([\w.]+)")


def read_checkpoint_payload(path) -> object:
    """``torch.load`` of a DENALI file with only :func:`allowed_globals` besides tensors; nothing else is unpickled.

    Raises
    ------
    UserError
        Missing or unreadable file; a file that needs another Python object (named) to load.
    """
    import zipfile

    path = Path(path)
    if not path.is_file():
        raise UserError(f"DENALI checkpoint {path} does not exist")
    if not zipfile.is_zipfile(path):
        raise UserError(f"{path} is not a readable torch file (not the zip archive torch.save writes)")
    try:
        with torch.serialization.safe_globals(allowed_globals()):
            return torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as exc:
        found = _GLOBAL.search(str(exc))
        what = f"the Python object {found.group(1)}" if found else "a Python object or operation outside the allow-list"
        raise UserError(f"{path}: refused, it needs {what} to load (only tensors and numpy arrays are read from "
                        "DENALI's checkpoints; nothing was unpickled)") from None
    except (RuntimeError, EOFError, OSError, ValueError) as exc:
        raise UserError(f"{path} is not a readable torch file ({str(exc).splitlines()[0][:120]})") from None


@dataclass(frozen=True, eq=False)
class DenaliCheckpoint:
    """One of DENALI's trained networks, ready to run.

    Attributes
    ----------
    name : str
        DENALI's file stem (``"obj_1dcnn"``, ...).
    task, model : str
    net : torch.nn.Module
        In eval mode on the CPU.
    classes : tuple of str or None
        Output order (DENALI's sorted names).
    real : float
        Its score on DENALI's real test split, from the file (loc: ``sqrt(test_mse)``, metres; else top-1).
    metric : {"loc_rmse", "top1_acc"}
    epoch : int or None
        The epoch DENALI kept.
    test_predictions : ndarray or None
        The real test split's predicted class indices in DENALI's test order (obj/size 1D CNN files).
    path : str
    """

    name: str
    task: str
    model: str
    net: nn.Module
    classes: tuple | None
    real: float
    metric: str
    epoch: int | None
    test_predictions: np.ndarray | None
    path: str


def _real_score(payload: dict, task: str, path: Path) -> float:
    try:
        if task == "loc":
            return float(np.sqrt(float(payload["test_mse"])))
        return float(payload["test_metrics"]["top1_acc"])
    except (KeyError, TypeError, ValueError):
        key = "test_mse" if task == "loc" else "test_metrics.top1_acc"
        raise UserError(f"{path} is not one of DENALI's checkpoints: it has no {key}") from None


def load_denali_checkpoint(path, name: str | None = None) -> DenaliCheckpoint:
    """Read one DENALI checkpoint and check it is the network its name says.

    Parameters
    ----------
    path : str or Path
    name : str, optional
        One of :data:`CHECKPOINTS` (default: the file's stem).

    Raises
    ------
    UserError
        An unknown name, an unsafe or unreadable file, or one that is not DENALI's network (an nlosplan
        checkpoint, weights of another shape, other class names); one line.
    """
    path = Path(path)
    name = name or path.stem
    if name not in CHECKPOINTS:
        raise UserError(f"{path}: no DENALI checkpoint is called {name!r}; read are {', '.join(CHECKPOINTS)}")
    task, model = CHECKPOINTS[name]
    payload = read_checkpoint_payload(path)
    if not isinstance(payload, dict) or not isinstance(payload.get("model_state_dict"), dict):
        hint = (" (an nlosplan checkpoint)" if isinstance(payload, dict) and "meta_json" in payload else "")
        raise UserError(f"{path} is not one of DENALI's checkpoints{hint}: it holds no model_state_dict")
    n_out = 2 if task == "loc" else len(_CLASSES[task])
    net = denali_model(model, task, _INPUT_SHAPE, n_out)
    try:
        net.load_state_dict(payload["model_state_dict"], strict=True)
    except (RuntimeError, TypeError) as exc:
        first = " ".join(str(exc).split())[:160]
        raise UserError(f"{path} is not DENALI's {name}: its weights do not fit that network ({first})") from None
    classes = None
    if task != "loc":
        classes = tuple(str(c) for c in payload.get("classes", _CLASSES[task]))
        if classes != _CLASSES[task]:
            raise UserError(f"{path} is not DENALI's {name}: its classes are {', '.join(classes[:6])}..., not "
                            f"DENALI's {', '.join(_CLASSES[task][:6])}...")
    preds = None
    if isinstance(payload.get("test_metrics"), dict) and "predictions" in payload["test_metrics"]:
        preds = np.asarray(payload["test_metrics"]["predictions"]).astype(np.int64)
    net.eval()
    epoch = payload.get("epoch")
    return DenaliCheckpoint(name=name, task=task, model=model, net=net, classes=classes,
                            real=_real_score(payload, task, path), metric="loc_rmse" if task == "loc" else "top1_acc",
                            epoch=None if epoch is None else int(epoch), test_predictions=preds, path=str(path))


def load_checkpoint_dir(folder, names=tuple(CHECKPOINTS)) -> list[DenaliCheckpoint]:
    """The checkpoints ``names`` from a folder (DENALI's ``benchmark/main_table/checkpoints``), all checked.

    Raises
    ------
    UserError
        The folder does not exist or lacks one of the files (named), or a file is refused.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise UserError(f"--checkpoints {folder}: no such folder (give DENALI's benchmark/main_table/checkpoints)")
    missing = [f"{n}.pth" for n in names if not (folder / f"{n}.pth").is_file()]
    if missing:
        raise UserError(f"--checkpoints {folder} lacks {', '.join(missing)} (DENALI's "
                        "benchmark/main_table/checkpoints holds them)")
    return [load_denali_checkpoint(folder / f"{n}.pth", n) for n in names]


def _inputs(ckpt: DenaliCheckpoint, histograms: np.ndarray) -> np.ndarray:
    """The network's input: raw counts, or the MLP's log1p + z-score with the set's own statistics."""
    x = np.asarray(histograms, dtype=np.float32)
    if ckpt.model == "mlp":
        x = np.log1p(np.clip(x, 0.0, None))
        x = ((x - float(x.mean())) / float(x.std() + 1e-6)).astype(np.float32, copy=False)
    return x


def bn_input_statistics(net: nn.Module, x: np.ndarray, batch: int = 512) -> dict:
    """Per-channel moments of every BatchNorm1d input of ``net`` on inputs ``x``, against its running statistics.

    Parameters
    ----------
    net : torch.nn.Module
        Run in eval mode (the running statistics normalise, as at inference).
    x : ndarray, shape (N, rows, cols, bins)
        The network's inputs.
    batch : int

    Returns
    -------
    dict
        Per layer name (``bn1``, ...): ``median_abs_z``, ``mean_log_var_ratio``, ``rms_log_var_ratio``,
        ``channels``, and per channel ``z`` and ``log_var_ratio`` (lists), where
        ``z = (mean - running_mean) / sqrt(running_var)`` and ``log_var_ratio = log(var / running_var)``,
        the moments over batch and time (biased variance, as BatchNorm normalises). Empty for a net without
        BatchNorm1d layers.
    """
    layers = {n: m for n, m in net.named_modules() if isinstance(m, nn.BatchNorm1d)}
    if not layers:
        return {}
    sums = {n: [torch.zeros(m.num_features, dtype=torch.float64) for _ in range(2)] + [0] for n, m in layers.items()}

    def hook(name):
        def record(_module, inputs, _output):
            v = inputs[0].detach().double()
            s = sums[name]
            s[0] += v.sum(dim=(0, 2))
            s[1] += (v * v).sum(dim=(0, 2))
            s[2] += v.shape[0] * v.shape[2]
        return record

    handles = [m.register_forward_hook(hook(n)) for n, m in layers.items()]
    net.eval()
    try:
        with torch.inference_mode():
            for i in range(0, len(x), batch):
                net(torch.from_numpy(np.ascontiguousarray(x[i:i + batch])))
    finally:
        for h in handles:
            h.remove()
    out = {}
    for name, m in layers.items():
        s1, s2, n = sums[name]
        mean = (s1 / n).numpy()
        var = np.maximum((s2 / n).numpy() - mean ** 2, 1e-30)
        rm, rv = m.running_mean.double().numpy(), m.running_var.double().numpy()
        z = (mean - rm) / np.sqrt(rv)
        lr = np.log(var / rv)
        out[name] = {"median_abs_z": float(np.median(np.abs(z))), "mean_log_var_ratio": float(lr.mean()),
                     "rms_log_var_ratio": float(np.sqrt(np.mean(lr ** 2))), "channels": int(len(z)),
                     "z": z.tolist(), "log_var_ratio": lr.tolist()}
    return out


def evaluate_checkpoints(checkpoints, histograms, labels, *, rows: dict | None = None, batch: int = 512,
                         on_done=None) -> list[dict]:
    """Run DENALI's real-trained networks on captures and score them against their real test scores.

    Parameters
    ----------
    checkpoints : sequence of DenaliCheckpoint
    histograms : ndarray, shape (N, 3, 3, 128)
        Counts (simulated captures of DENALI's protocol, say), rows as ``labels``.
    labels : pandas.DataFrame
        ``object``, ``size``, ``lights``, ``x``, ``y`` per row (nlosplan names).
    rows : dict of str to array_like of int, optional
        Rows each task scores (e.g. the scenes of DENALI's real test split); default all.
        The MLP's z-score always uses all ``histograms`` (DENALI's z-score is over the whole set).
    batch : int
    on_done : callable, optional
        Called with each checkpoint's name once it is scored (a progress bar's step).

    Returns
    -------
    list of dict
        One per checkpoint: ``name``, ``task``, ``model``, ``metric``, ``simulated`` (its score here),
        ``real`` (on DENALI's real test split), ``ratio`` (simulated / real), ``n``, ``by_lights``
        ({"on", "off"} scores), ``chance`` (loc: the RMSE of predicting the mean position; classes:
        1 / number of classes), ``modal_prediction`` and ``modal_share`` (classes: the most frequent
        predicted class and its share), ``bn`` (:func:`bn_input_statistics`, without the MLP's none).

    Raises
    ------
    UserError
        Histograms of another shape than DENALI's (3, 3, 128), or labels that do not match them.
    """
    x_all = np.asarray(histograms, dtype=np.float32)
    if x_all.ndim != 4 or x_all.shape[1:] != _INPUT_SHAPE:
        raise UserError(f"DENALI's networks take (N, 3, 3, 128) histograms (its 3x3 unit, 128 bins), got "
                        f"{x_all.shape}")
    if len(labels) != len(x_all):
        raise UserError(f"{len(labels)} label rows for {len(x_all)} histograms")
    lights = labels["lights"].astype(str).to_numpy()
    out = []
    for ck in checkpoints:
        idx = np.arange(len(x_all)) if rows is None or ck.task not in rows else np.asarray(rows[ck.task])
        x = _inputs(ck, x_all)[idx]
        with torch.inference_mode():
            y_out = torch.cat([ck.net(torch.from_numpy(np.ascontiguousarray(x[i:i + batch])))
                               for i in range(0, len(x), batch)]).double().numpy()
        truth = task_labels(labels.iloc[idx], ck.task)
        res = {"name": ck.name, "task": ck.task, "model": ck.model, "metric": ck.metric, "n": int(len(idx))}
        if ck.task == "loc":
            score = lambda m: loc_rmse(y_out[m], truth[m])  # noqa: E731
            res["chance"] = loc_rmse(np.broadcast_to(truth.mean(axis=0), truth.shape), truth)
        else:
            t = np.array([ck.classes.index(v) for v in truth])
            score = lambda m: top1_accuracy(y_out[m], t[m])  # noqa: E731
            counts = np.bincount(y_out.argmax(axis=1), minlength=len(ck.classes))
            res.update(chance=1.0 / len(ck.classes), modal_prediction=ck.classes[int(counts.argmax())],
                       modal_share=float(counts.max() / counts.sum()))
        everything = np.ones(len(idx), bool)
        res["simulated"] = score(everything)
        res["real"] = ck.real
        res["ratio"] = res["simulated"] / ck.real
        res["by_lights"] = {li: score(lights[idx] == li) for li in ("on", "off") if (lights[idx] == li).any()}
        res["bn"] = bn_input_statistics(ck.net, x, batch)
        out.append(res)
        if on_done is not None:
            on_done(ck.name)
    return out
