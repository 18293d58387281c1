"""Checkpoints of trained models: weights and metadata only, written atomically, loaded without pickle.

A checkpoint is one ``torch.save`` file holding a format tag, the model's
``state_dict`` (tensors) and the metadata of
:meth:`~nlosplan.tasks.training_types.TrainedModel.meta` as a JSON string: nothing
that needs Python's pickle to load, so :func:`load_checkpoint` reads it with
``torch.load(weights_only=True)`` and rebuilds the model from the recorded
:class:`~nlosplan.tasks.models.ModelSpec`.
"""

from __future__ import annotations

import json
import pickle
from pathlib import Path

import torch

from nlosplan.errors import UserError
from nlosplan.files import atomic_path
from nlosplan.tasks.models import ModelSpec, model_from_spec
from nlosplan.tasks.training_types import Preprocessing, TrainConfig, TrainedModel

__all__ = ["CHECKPOINT_FORMAT", "load_checkpoint", "save_checkpoint"]

CHECKPOINT_FORMAT = "nlosplan.tasks.checkpoint/1"
#: Layer names of the MLP and the 1D CNN before they took DENALI's (``fc1``, ``conv1``, ``bn1``, ...): files
#: written then load through this renaming.
_LEGACY_KEYS = {"mlp": {"net.1.": "fc1.", "net.4.": "fc2.", "net.7.": "fc3.", "net.10.": "fc4."},
                "cnn1d": {"features.0.": "conv1.", "features.1.": "bn1.", "features.3.": "conv2.",
                          "features.4.": "bn2.", "features.6.": "conv3.", "features.7.": "bn3."}}


def _renamed(state: dict, model: str) -> dict:
    """``state`` with the layer names of an older file of ``model`` renamed to today's."""
    table = _LEGACY_KEYS.get(model, {})
    out = {}
    for key, value in state.items():
        old = next((o for o in table if key.startswith(o)), None)
        out[table[old] + key[len(old):] if old else key] = value
    return out


def save_checkpoint(path, trained) -> Path:
    """Write a trained model to ``path`` atomically (a temporary file, then ``os.replace``).

    The file holds only tensors, strings and plain containers: the
    ``state_dict``, a format tag and the metadata of :meth:`TrainedModel.meta`
    as a JSON string, so that :func:`load_checkpoint` can read it with
    ``torch.load(weights_only=True)``. A kill during the write leaves the
    previous file (or none), never half of one.

    Parameters
    ----------
    path : str or Path
    trained : TrainedModel

    Returns
    -------
    Path
        ``path``.
    """
    path = Path(path)
    payload = {"format": CHECKPOINT_FORMAT,
               "state_dict": {k: v.detach().cpu().clone() for k, v in trained.model.state_dict().items()},
               "meta_json": json.dumps(trained.meta())}
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            torch.save(payload, fh)
    return path


def load_checkpoint(path):
    """Read a checkpoint of :func:`save_checkpoint` and rebuild its model (no code is unpickled).

    Returns
    -------
    TrainedModel
        In eval mode on the CPU, with the recorded preprocessing, classes,
        history and settings.

    Raises
    ------
    UserError
        Missing file, a file that would need pickle to load (not written by
        nlosplan, possibly unsafe), or one of another format.
    """
    path = Path(path)
    if not path.is_file():
        raise UserError(f"checkpoint {path} does not exist")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError:
        raise UserError(f"{path} needs pickle to load (it holds Python objects, not only weights); refused: "
                        "only checkpoints written by nlosplan are read") from None
    except (RuntimeError, EOFError, OSError, ValueError) as exc:
        raise UserError(f"{path} is not a readable checkpoint ({str(exc).splitlines()[0]})") from None
    if not isinstance(payload, dict) or payload.get("format") != CHECKPOINT_FORMAT:
        raise UserError(f"{path} is not an nlosplan checkpoint (expected format {CHECKPOINT_FORMAT})")
    meta = json.loads(payload["meta_json"])
    spec = ModelSpec.from_dict(meta["spec"])
    net = model_from_spec(spec)
    try:
        net.load_state_dict(_renamed(payload["state_dict"], spec.name), strict=True)
    except RuntimeError as exc:
        raise UserError(f"{path}: weights do not fit model {spec.name} ({str(exc).splitlines()[0]})") from None
    net.eval()
    cfg = meta["config"]
    return TrainedModel(
        model=net, spec=spec, preprocessing=Preprocessing(**meta["preprocessing"]), config=TrainConfig(**cfg),
        classes=None if meta["classes"] is None else tuple(meta["classes"]),
        target_mean=None if meta["target_mean"] is None else tuple(meta["target_mean"]),
        target_std=None if meta["target_std"] is None else tuple(meta["target_std"]),
        history=meta["history"], best_epoch=int(meta["best_epoch"]), stopped=meta["stopped"],
        train_seconds=float(meta["train_seconds"]), n_train=int(meta["n_train"]), n_val=int(meta["n_val"]),
        val_rows=tuple(meta.get("val_rows", ())))
