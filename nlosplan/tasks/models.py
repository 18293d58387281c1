"""Torch models of the DENALI benchmark: MLP, 1D CNN, 3D CNN and Transformer, for three tasks.

The architectures follow DENALI's ``benchmark/main_table/models.py``
(github.com/NikhilBehari/denali), with two changes:

- no ``Lazy`` modules: every layer size is computed from the input shape
  ``(rows, cols, bins)`` given to :func:`build_model`, so a model can be
  rebuilt from its recorded :class:`ModelSpec` and its weights loaded at once;
- a ``width`` factor scales every hidden size (channels, units, ``d_model``),
  so tests and CI can train small versions; ``width=1`` is the paper's size.

Tasks
-----
``"loc"``
    Regression to the object's (x, y), 2 outputs (metres, or standardized
    metres: the training code decides).
``"shape"``
    30-way object classification (logits).
``"size"``
    2-way size classification, 4 in vs 8 in (logits).

Input
-----
Every model takes histograms of shape ``(N, rows, cols, bins)`` (after the
preprocessing of :mod:`nlosplan.tasks.training`) and returns ``(N, n_outputs)``.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import torch
from torch import nn

from nlosplan.errors import UserError

__all__ = ["MODEL_NAMES", "TASKS", "TASK_LABEL", "ModelSpec", "build_model", "check_names", "model_from_spec",
           "n_parameters"]

from nlosplan.tasks.names import MODEL_NAMES, TASK_LABEL, TASKS, check_names  # noqa: E402,F401 (re-exported)


def _scaled(n: int, width: float, minimum: int = 4) -> int:
    """``n * width`` rounded, at least ``minimum``."""
    return max(minimum, int(round(n * width)))


class MLP(nn.Module):
    """Four fully connected layers (512/256/128 x width, GELU, dropout), DENALI's ``SmallMLP``.

    Layer names are DENALI's (``fc1`` .. ``fc4``, one ``dropout`` used after each of the first three), so
    DENALI's ``SmallMLP`` state dicts load into a ``width=1`` model with ``strict=True``.

    Parameters
    ----------
    in_features : int
        ``rows * cols * bins``.
    n_outputs : int
    width : float
    dropout : float
    """

    def __init__(self, in_features: int, n_outputs: int, width: float = 1.0, dropout: float = 0.1):
        super().__init__()
        h1, h2, h3 = (_scaled(n, width) for n in (512, 256, 128))
        self.fc1 = nn.Linear(in_features, h1)
        self.fc2 = nn.Linear(h1, h2)
        self.fc3 = nn.Linear(h2, h3)
        self.fc4 = nn.Linear(h3, n_outputs)
        self.dropout = nn.Dropout(dropout)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(N, rows, cols, bins)`` -> ``(N, n_outputs)``."""
        x = x.flatten(1)
        for fc in (self.fc1, self.fc2, self.fc3):
            x = self.dropout(nn.functional.gelu(fc(x)))
        return self.fc4(x)


class CNN1D(nn.Module):
    """Three Conv1d-BatchNorm-GELU blocks over time, zones as channels; DENALI's ``MediumConv1DNet``.

    Channels 128 -> 128 -> 64 (x width), kernels 5/3/3, then global average
    pooling over time and a two-layer head (64 -> 32 -> outputs, x width).
    Layer names are DENALI's (``conv1``, ``bn1`` .. ``conv3``, ``bn3``; ``head`` for the classifier), so
    DENALI's state dicts load into a ``width=1`` model with ``strict=True``.

    Parameters
    ----------
    zones : int
        ``rows * cols`` input channels.
    n_outputs : int
    width : float
    dropout : float
    denali_regressor : bool
        DENALI's regressor head (``MediumConv1DNetReg``) instead of ``head``: ``pool``, ``mlp`` (Linear,
        GELU, Dropout), ``out_linear``, and ``out_tanh``, a layer DENALI's ``forward`` never uses but its
        state dicts hold. The same function as ``head``; used by DENALI's recipe
        (:mod:`nlosplan.tasks.denali_recipe`).
    """

    def __init__(self, zones: int, n_outputs: int, width: float = 1.0, dropout: float = 0.1,
                 denali_regressor: bool = False):
        super().__init__()
        c1, c3 = _scaled(128, width), _scaled(64, width)
        head = _scaled(32, width)
        self.conv1 = nn.Conv1d(zones, c1, kernel_size=5, padding=2, bias=False)
        self.bn1 = nn.BatchNorm1d(c1)
        self.conv2 = nn.Conv1d(c1, c1, kernel_size=3, padding=1, bias=False)
        self.bn2 = nn.BatchNorm1d(c1)
        self.conv3 = nn.Conv1d(c1, c3, kernel_size=3, padding=1, bias=False)
        self.bn3 = nn.BatchNorm1d(c3)
        self.denali_regressor = bool(denali_regressor)
        if self.denali_regressor:
            self.pool = nn.AdaptiveAvgPool1d(1)
            self.mlp = nn.Sequential(nn.Linear(c3, head), nn.GELU(), nn.Dropout(dropout))
            self.out_linear = nn.Linear(head, n_outputs)
            self.out_tanh = nn.Linear(head, n_outputs)
        else:
            self.head = nn.Sequential(nn.AdaptiveAvgPool1d(1), nn.Flatten(), nn.Linear(c3, head), nn.GELU(),
                                      nn.Dropout(dropout), nn.Linear(head, n_outputs))

    def features(self, x: torch.Tensor) -> torch.Tensor:
        """``(N, rows, cols, bins)`` -> ``(N, rows*cols, bins)`` -> the third block's output ``(N, c3, bins)``."""
        x = x.flatten(1, 2)
        for conv, bn in ((self.conv1, self.bn1), (self.conv2, self.bn2), (self.conv3, self.bn3)):
            x = nn.functional.gelu(bn(conv(x)))
        return x

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(N, rows, cols, bins)`` -> ``(N, n_outputs)``."""
        if self.denali_regressor:
            return self.out_linear(self.mlp(self.pool(self.features(x)).squeeze(-1)))
        return self.head(self.features(x))


class CNN3DDeep(nn.Module):
    """Three Conv3d-BatchNorm-GELU blocks over (rows, cols, time); DENALI's ``DeepConv3DNet``.

    Kernel (3, 3, 10) with "same" padding, channels 128 -> 128 -> 64 (x width),
    global average pooling and a two-layer head. DENALI uses it for size
    classification and localization.
    """

    def __init__(self, n_outputs: int, width: float = 1.0, dropout: float = 0.1):
        super().__init__()
        c1, c3 = _scaled(128, width), _scaled(64, width)
        k = (3, 3, 10)

        def same():  # torch's padding="same" for this kernel (extra bin on the right), without its copy warning
            return nn.ZeroPad3d((4, 5, 1, 1, 1, 1))

        self.features = nn.Sequential(
            same(), nn.Conv3d(1, c1, k, bias=False), nn.BatchNorm3d(c1), nn.GELU(),
            same(), nn.Conv3d(c1, c1, k, bias=False), nn.BatchNorm3d(c1), nn.GELU(),
            same(), nn.Conv3d(c1, c3, k, bias=False), nn.BatchNorm3d(c3), nn.GELU(),
        )
        self.head = nn.Sequential(nn.AdaptiveAvgPool3d(1), nn.Flatten(), nn.Linear(c3, c3 // 2), nn.GELU(),
                                  nn.Dropout(dropout), nn.Linear(c3 // 2, n_outputs))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(N, rows, cols, bins)`` -> volume ``(N, 1, rows, cols, bins)`` -> ``(N, n_outputs)``."""
        return self.head(self.features(x.unsqueeze(1)))


class CNN3DStrided(nn.Module):
    """One strided Conv3d block and an MLP head; DENALI's ``MediumConv3DOverCNet`` (shape classification).

    Kernel (5, 5, 16), stride (2, 2, 4), padding (2, 2, 8), 32 x width
    channels, BatchNorm + GELU, then 512/256/128 (x width) GELU + dropout.

    Parameters
    ----------
    input_shape : tuple of int
        ``(rows, cols, bins)``, used to size the first linear layer.
    """

    KERNEL, STRIDE, PAD = (5, 5, 16), (2, 2, 4), (2, 2, 8)

    def __init__(self, input_shape: tuple[int, int, int], n_outputs: int, width: float = 1.0, dropout: float = 0.1):
        super().__init__()
        c = _scaled(32, width)
        out = [(n + 2 * p - k) // s + 1 for n, k, s, p in zip(input_shape, self.KERNEL, self.STRIDE, self.PAD)]
        if min(out) < 1:
            raise UserError(f"input shape {input_shape} is too small for the strided 3D CNN")
        h1, h2, h3 = (_scaled(n, width) for n in (512, 256, 128))
        self.features = nn.Sequential(nn.Conv3d(1, c, self.KERNEL, stride=self.STRIDE, padding=self.PAD, bias=False),
                                      nn.BatchNorm3d(c), nn.GELU(), nn.Flatten())
        self.head = nn.Sequential(
            nn.Linear(c * math.prod(out), h1), nn.GELU(), nn.Dropout(dropout),
            nn.Linear(h1, h2), nn.GELU(), nn.Dropout(dropout),
            nn.Linear(h2, h3), nn.GELU(), nn.Dropout(dropout),
            nn.Linear(h3, n_outputs),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(N, rows, cols, bins)`` -> ``(N, n_outputs)``."""
        return self.head(self.features(x.unsqueeze(1)))


class Transformer(nn.Module):
    """Class-token Transformer encoder over time tokens; DENALI's ``TransformerNet``.

    One token per time bin carrying the ``rows * cols`` zone values, a linear
    embedding to ``d_model`` (256 x width, a multiple of 8) scaled by
    sqrt(d_model), learned positional encoding, a class token, LayerNorm,
    4 pre-norm encoder layers (8 heads, feed-forward 4 x d_model, GELU),
    a final LayerNorm and a head on the class token (LayerNorm for
    classification, as DENALI) of d_model -> d_model / 2 -> outputs.

    Parameters
    ----------
    zones, bins : int
        Token features and sequence length.
    classify : bool
        Classification head (True) or regression head (False).
    """

    def __init__(self, zones: int, bins: int, n_outputs: int, width: float = 1.0, dropout: float = 0.1,
                 classify: bool = True, n_heads: int = 8, n_layers: int = 4):
        super().__init__()
        d = max(n_heads * 2, int(round(256 * width / n_heads)) * n_heads)
        self.d_model = d
        self.token_embed = nn.Linear(zones, d)
        self.pos_encoding = nn.Parameter(torch.empty(1, bins, d))
        nn.init.normal_(self.pos_encoding, mean=0.0, std=0.02)
        self.cls_token = nn.Parameter(torch.zeros(1, 1, d))
        self.input_norm = nn.LayerNorm(d)
        self.pos_drop = nn.Dropout(dropout)
        layer = nn.TransformerEncoderLayer(d_model=d, nhead=n_heads, dim_feedforward=4 * d, dropout=dropout,
                                           activation="gelu", batch_first=True, norm_first=True)
        self.encoder = nn.TransformerEncoder(layer, num_layers=n_layers, enable_nested_tensor=False)
        self.final_norm = nn.LayerNorm(d)
        first = [nn.LayerNorm(d)] if classify else []
        self.head = nn.Sequential(*first, nn.Linear(d, d // 2), nn.GELU(), nn.Dropout(dropout),
                                  nn.Linear(d // 2, n_outputs))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(N, rows, cols, bins)`` -> tokens ``(N, bins, rows*cols)`` -> ``(N, n_outputs)``."""
        tokens = x.flatten(1, 2).transpose(1, 2)
        h = self.token_embed(tokens) * math.sqrt(self.d_model) + self.pos_encoding
        h = torch.cat([self.cls_token.expand(h.shape[0], 1, -1), h], dim=1)
        h = self.encoder(self.pos_drop(self.input_norm(h)))
        return self.head(self.final_norm(h)[:, 0])


@dataclass(frozen=True)
class ModelSpec:
    """Everything needed to rebuild a model (recorded in checkpoints).

    Parameters
    ----------
    name : {"mlp", "cnn1d", "cnn3d", "transformer"}
    task : {"loc", "shape", "size"}
    input_shape : tuple of int
        ``(rows, cols, bins)`` of one histogram.
    n_outputs : int
        2 for ``"loc"``; the number of classes otherwise.
    width : float
        Scale of every hidden size (1 = the paper's).
    dropout : float
    """

    name: str
    task: str
    input_shape: tuple[int, int, int]
    n_outputs: int
    width: float = 1.0
    dropout: float = 0.1

    def to_dict(self) -> dict:
        """Plain JSON-able dict (``input_shape`` as a list)."""
        d = asdict(self)
        d["input_shape"] = list(self.input_shape)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "ModelSpec":
        """Inverse of :meth:`to_dict`."""
        return cls(name=str(d["name"]), task=str(d["task"]), input_shape=tuple(int(v) for v in d["input_shape"]),
                   n_outputs=int(d["n_outputs"]), width=float(d["width"]), dropout=float(d["dropout"]))


def _check_spec(name, task, input_shape, n_outputs, width, dropout) -> tuple[int, int, int]:
    if name not in MODEL_NAMES:
        raise UserError(f"unknown model {name!r}; allowed: {', '.join(MODEL_NAMES)}")
    if task not in TASKS:
        raise UserError(f"unknown task {task!r}; allowed: {', '.join(TASKS)}")
    shape = tuple(int(v) for v in input_shape)
    if len(shape) == 4:  # (N, rows, cols, bins) given
        shape = shape[1:]
    if len(shape) != 3 or min(shape) < 1:
        raise UserError(f"input shape {tuple(input_shape)} must be (rows, cols, bins) or (N, rows, cols, bins)")
    if task == "loc" and n_outputs != 2:
        raise UserError(f"task 'loc' regresses (x, y): n_outputs must be 2, got {n_outputs}")
    if task != "loc" and n_outputs < 2:
        raise UserError(f"task {task!r} needs at least 2 classes, got {n_outputs}")
    if not (math.isfinite(width) and width > 0):
        raise UserError(f"width={width} must be > 0")
    if not 0 <= dropout < 1:
        raise UserError(f"dropout={dropout} must be in [0, 1)")
    return shape  # type: ignore[return-value]


def build_model(name: str, task: str, input_shape, n_outputs: int, *, width: float = 1.0,
                dropout: float = 0.1) -> nn.Module:
    """A fresh model of the DENALI benchmark.

    Parameters
    ----------
    name : {"mlp", "cnn1d", "cnn3d", "transformer"}
    task : {"loc", "shape", "size"}
        For ``cnn3d`` the task picks DENALI's variant: the strided single-block
        network for ``"shape"``, the deep three-block one for ``"loc"`` and
        ``"size"``; for ``transformer`` it picks the head (LayerNorm first for
        classification).
    input_shape : tuple of int
        ``(rows, cols, bins)`` or ``(N, rows, cols, bins)``.
    n_outputs : int
        2 for ``"loc"``; the number of classes otherwise.
    width : float
        Scale of every hidden size (1 = the paper's; 0.25 trains ~10x faster on a CPU).
    dropout : float

    Returns
    -------
    torch.nn.Module
        Maps ``(N, rows, cols, bins)`` float32 to ``(N, n_outputs)``; in
        training mode, parameters initialised from torch's global generator.

    Raises
    ------
    UserError
        Unknown name or task, a bad shape, width or number of outputs.

    Examples
    --------
    >>> m = build_model("cnn1d", "shape", (3, 3, 128), 30, width=0.25)
    >>> m(torch.zeros(4, 3, 3, 128)).shape
    torch.Size([4, 30])
    """
    rows, cols, bins = _check_spec(name, task, input_shape, n_outputs, width, dropout)
    if name == "mlp":
        return MLP(rows * cols * bins, n_outputs, width, dropout)
    if name == "cnn1d":
        return CNN1D(rows * cols, n_outputs, width, dropout)
    if name == "cnn3d":
        if task == "shape":
            return CNN3DStrided((rows, cols, bins), n_outputs, width, dropout)
        return CNN3DDeep(n_outputs, width, dropout)
    return Transformer(rows * cols, bins, n_outputs, width, dropout, classify=task != "loc")


def model_from_spec(spec: ModelSpec) -> nn.Module:
    """:func:`build_model` from a :class:`ModelSpec`."""
    return build_model(spec.name, spec.task, spec.input_shape, spec.n_outputs, width=spec.width,
                       dropout=spec.dropout)


def n_parameters(model: nn.Module) -> int:
    """Number of trainable parameters."""
    return int(sum(p.numel() for p in model.parameters() if p.requires_grad))
