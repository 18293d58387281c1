"""``nlosplan benchmark``: train and test the four models on the three DENALI tasks; print the paper's table."""

from __future__ import annotations

import argparse
import sys
import time
from typing import Callable

from nlosplan.cli.common import emit, note, sub_parser
from nlosplan.errors import UserError
from nlosplan.tasks.benchmark import DEFAULT_EPOCHS, DEFAULT_PATIENCE, DEFAULT_WIDTH, PROFILES, SMALL
from nlosplan.tasks.models import MODEL_NAMES, TASKS
from nlosplan.tasks.splits import SPLITS

DEFAULT_OUT = "nlosplan-out/benchmark"
_INT_COLUMNS = ("position", "repeat")


def _names(kind: str, allowed) -> Callable[[str], list[str]]:
    """An argparse type: a comma-separated list of names from ``allowed``."""

    def parse(text: str) -> list[str]:
        names = [v.strip() for v in text.split(",") if v.strip()]
        bad = [n for n in names if n not in allowed]
        if bad or not names:
            raise argparse.ArgumentTypeError(f"unknown {kind} {', '.join(bad) or '(none)'}; allowed: {', '.join(allowed)}")
        return list(dict.fromkeys(names))

    return parse


def _number(cast, *, zero_ok: bool = False) -> Callable[[str], float]:
    """An argparse type: a number > 0 (>= 0 with ``zero_ok``)."""

    def parse(text: str):
        try:
            value = cast(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not {'an integer' if cast is int else 'a number'}") from None
        if not (value >= 0 if zero_ok else value > 0) or value != value:
            raise argparse.ArgumentTypeError(f"{text} must be {'>= 0' if zero_ok else '> 0'}")
        return value

    return parse


def parse_where(text: str | None) -> dict:
    """``lights=off,zones=3x3,object=A|S`` as ``{"lights": "off", "zones": "3x3", "object": ["A", "S"]}``."""
    where: dict = {}
    for item in (text or "").split(","):
        if not item.strip():
            continue
        key, sep, value = item.partition("=")
        key, value = key.strip(), value.strip()
        if not sep or not key or not value:
            raise UserError(f"--where {text!r}: each filter must look like column=value (alternatives a|b), "
                            "e.g. lights=off,zones=3x3")
        values = [v.strip() for v in value.split("|") if v.strip()]
        if key in _INT_COLUMNS:
            try:
                values = [int(v) for v in values]
            except ValueError:
                raise UserError(f"--where {key}={value}: {key} takes integers") from None
        where[key] = values[0] if len(values) == 1 else values
    return where


def _load_dataset(store: str, where: dict):
    """The captures of ``store`` that match ``where`` (a :class:`~nlosplan.tasks.dataset.Dataset`)."""
    from nlosplan.tasks.store import CaptureStore

    with CaptureStore(store, create=False) as st:
        return st.load(**where)


def _progress_bar(args, n_entries: int):
    """Progress on stderr: a tqdm bar over the (model, task) entries on a terminal, else one line per entry."""
    if not sys.stderr.isatty():
        def log(event: dict) -> None:  # a log file: one line per finished entry (stdout stays clean for --json)
            if event["event"] == "start":
                log.t0 = time.perf_counter()
            elif event["event"] == "done":
                took = f" in {time.perf_counter() - log.t0:.0f} s" if getattr(log, "t0", None) else " (n/a)"
                log.t0 = None
                print(f"benchmark: [{event['index'] + 1}/{event['total']}] {event['model']} {event['task']}{took}",
                      file=sys.stderr, flush=True)

        return None, log
    from tqdm import tqdm

    bar = tqdm(total=n_entries, desc="benchmark", unit="model", file=sys.stderr, leave=False)

    def progress(event: dict) -> None:
        if event["event"] == "epoch":
            rec = event["record"]
            val = "" if rec["val_loss"] is None else f" val {rec['val_loss']:.3g}"
            bar.set_postfix_str(f"{event['model']} {event['task']} epoch {rec['epoch']}{val}")
        elif event["event"] == "done":
            bar.update(1)

    return bar, progress


def _cmd_benchmark(args) -> int:
    import torch

    from nlosplan.reports.benchmark_table import benchmark_text, write_benchmark
    from nlosplan.tasks.benchmark import run_benchmark

    if args.threads is not None:
        torch.set_num_threads(args.threads)
    epochs, width = args.epochs, args.width
    if args.small:
        epochs = SMALL["epochs"] if epochs is None else epochs
        width = SMALL["width"] if width is None else width
    where = parse_where(args.where)
    note(args, f"loading {args.store} ({', '.join(f'{k}={v}' for k, v in where.items()) or 'all captures'}) ...")
    dataset = _load_dataset(args.store, where)
    bar, progress = _progress_bar(args, len(args.models) * len(args.tasks))
    try:
        result = run_benchmark(dataset, models=args.models, tasks=args.tasks, split=args.split, seed=args.seed,
                               epochs=epochs, width=DEFAULT_WIDTH if width is None else width,
                               average_repeats=not args.keep_repeats, profile=args.profile,
                               patience=None if args.patience == 0 else args.patience, max_seconds=args.max_seconds,
                               checkpoint_dir=f"{args.out}/models" if args.save_models else None, progress=progress)
    finally:
        if bar is not None:
            bar.close()
    result["config"]["store"] = str(args.store)
    result["config"]["where"] = where
    files = write_benchmark(result, args.out)
    result["files"] = files
    emit(args, result, benchmark_text(result) + "\n\n" + "\n".join(f"wrote {k}: {v}" for k, v in files.items()))
    return 0


BENCHMARK_DESCRIPTION = f"""\
Train and test the DENALI benchmark models (MLP, 1D CNN, 3D CNN, Transformer)
on its three tasks (localization, 30-way shape, 4 in vs 8 in size) and print
the paper's table: models as rows; per task the metrics overall and by size,
class group (numbers, letters, shapes) and near/far quadrant.

Data: the captures of --store that match --where, each scene's repeats
averaged (as DENALI). Split: 70/30 random (stratified for classification,
seed 42), or held-out positions, object classes or sizes ('sizes' trains on
4 in, 'sizes:8in' on 8 in). Training: Adam, early stopping on a validation
part of the training set, the best epoch kept.

Cost (2 CPU cores, 6,000 scenes, --threads 1): MLP and 1D CNN seconds to
a minute per task, the deep 3D CNN 35-45 s and the Transformer 60 s per epoch (see
README "NLOS tasks"; --max-seconds caps each). --small
(= --epochs {SMALL['epochs']} --width {SMALL['width']}) is the quick run for CI.

Writes benchmark.csv (models as rows, task/metric/group columns), benchmark.md
and benchmark.json (everything, with the settings and timings) into --out."""


def add_training_options(group) -> None:
    """Training options shared by ``nlosplan benchmark`` and the studies built on it."""
    group.add_argument("--small", action="store_true",
                       help=f"quick run: --epochs {SMALL['epochs']} --width {SMALL['width']} unless given")
    group.add_argument("--epochs", type=_number(int), metavar="N",
                       help=f"epoch cap per model (default: {DEFAULT_EPOCHS}; with --profile denali, DENALI's)")
    group.add_argument("--width", type=_number(float), metavar="F",
                       help=f"model size factor, 1 = the paper's (default: {DEFAULT_WIDTH})")
    group.add_argument("--patience", type=_number(int, zero_ok=True), default=DEFAULT_PATIENCE, metavar="N",
                       help="early-stopping patience in epochs, 0 for none (default: %(default)s)")
    group.add_argument("--max-seconds", type=_number(float), metavar="S", help="wall-clock budget per model")
    group.add_argument("--profile", choices=PROFILES, default="cpu",
                       help="training settings: cpu (lr 1e-3, batch 64, log1p + z-score) or denali "
                            "(its per-model lr, batch, epochs, preprocessing) (default: cpu)")
    group.add_argument("--keep-repeats", action="store_true", help="train on every repeat instead of their mean")


def add(sub) -> None:
    """The ``benchmark`` subcommand."""
    p = sub_parser(sub, "benchmark", "benchmark", "train and test the four DENALI models on the three tasks; "
                   "print the paper's table", description=BENCHMARK_DESCRIPTION)
    p.add_argument("--store", required=True, metavar="PATH", help="capture store (SQLite file)")
    p.add_argument("--where", metavar="COL=V,...", help="filter captures, e.g. lights=off,zones=3x3 "
                                                         "(alternatives with |, quoted: 'object=A|S')")
    p.add_argument("--models", type=_names("model(s)", MODEL_NAMES), default=list(MODEL_NAMES), metavar="M,M",
                   help=f"models (default: {','.join(MODEL_NAMES)})")
    p.add_argument("--tasks", type=_names("task(s)", TASKS), default=list(TASKS), metavar="T,T",
                   help=f"tasks (default: {','.join(TASKS)})")
    p.add_argument("--split", choices=SPLITS, default="random", help="train/test split (default: random)")
    add_training_options(p)
    p.add_argument("--seed", type=int, default=42, help="seed of the split and training (default: 42)")
    p.add_argument("--threads", type=_number(int), metavar="N", help="torch CPU threads (default: torch's)")
    p.add_argument("--save-models", action="store_true", help="also write each model's checkpoint to OUT/models")
    p.add_argument("--out", default=DEFAULT_OUT, metavar="DIR", help="output folder (default: %(default)s)")
    p.add_argument("--json", action="store_true", help="print the whole result as JSON")
    p.set_defaults(func=_cmd_benchmark)
