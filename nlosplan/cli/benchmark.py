"""``nlosplan benchmark``: train and test the four models on the three DENALI tasks; print the paper's table."""

from __future__ import annotations

import sys
import time
from contextlib import contextmanager

from nlosplan.cli.common import emit, names_type, note, number_type, parse_where, progress_bar, sub_parser
from nlosplan.tasks.names import (DEFAULT_EPOCHS, DEFAULT_PATIENCE, DEFAULT_WIDTH, MODEL_NAMES, PROFILES, SMALL,
                                  SPLITS, TASKS)

DEFAULT_OUT = "nlosplan-out/benchmark"

def _load_dataset(store: str, where: dict):
    """The captures of ``store`` that match ``where`` (a :class:`~nlosplan.data.dataset.Dataset`)."""
    from nlosplan.data.store import CaptureStore

    with CaptureStore(store, create=False) as st:
        return st.load(**where)


def _log_line(event: dict) -> None:
    """Progress for a log file: one stderr line per finished entry (stdout stays clean for --json)."""
    if event["event"] == "start":
        _log_line.t0 = time.perf_counter()
    elif event["event"] == "done":
        t0, _log_line.t0 = getattr(_log_line, "t0", None), None
        took = " (n/a)" if t0 is None else f" in {time.perf_counter() - t0:.0f} s"
        print(f"benchmark: [{event['index'] + 1}/{event['total']}] {event['model']} {event['task']}{took}",
              file=sys.stderr, flush=True)


@contextmanager
def _progress(args, n_entries: int):
    """Progress on stderr: a tqdm bar over the (model, task) entries on a terminal, else one line per entry."""
    if not sys.stderr.isatty():
        yield _log_line
        return
    with progress_bar(args, n_entries, "benchmark", "model") as bar:
        def update(event: dict) -> None:
            if event["event"] == "epoch":
                rec = event["record"]
                val = "" if rec["val_loss"] is None else f" val {rec['val_loss']:.3g}"
                bar.set_postfix_str(f"{event['model']} {event['task']} epoch {rec['epoch']}{val}")
            elif event["event"] == "done":
                bar.update(1)

        yield None if bar is None else update


def _cmd_benchmark(args) -> int:
    import torch

    from nlosplan.reports.benchmark_table import benchmark_text, write_benchmark
    from nlosplan.tasks.benchmark import run_benchmark

    if args.threads is not None:
        torch.set_num_threads(args.threads)
    where = parse_where(args.where)
    note(args, f"loading {args.store} ({', '.join(f'{k}={v}' for k, v in where.items()) or 'all captures'}) ...")
    dataset = _load_dataset(args.store, where)
    with _progress(args, len(args.models) * len(args.tasks)) as progress:
        result = run_benchmark(dataset, models=args.models, tasks=args.tasks, split=args.split, seed=args.seed,
                               checkpoint_dir=f"{args.out}/models" if args.save_models else None, progress=progress,
                               **training_options(args))
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
class group (numbers, letters, shapes) and near/far quadrant. Localization
RMSE (loc_rmse) is DENALI's: sqrt of the mean of the squared x and y errors
pooled over the N x 2 entries (not the 2-D distance, which is sqrt 2 larger).

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
    group.add_argument("--epochs", type=number_type(int), metavar="N",
                       help=f"epoch cap per model (default: {DEFAULT_EPOCHS}; with --profile denali, DENALI's)")
    group.add_argument("--width", type=number_type(float), metavar="F",
                       help=f"model size factor, 1 = the paper's (default: {DEFAULT_WIDTH})")
    group.add_argument("--patience", type=number_type(int, zero_ok=True), default=DEFAULT_PATIENCE, metavar="N",
                       help="early-stopping patience in epochs, 0 for none (default: %(default)s)")
    group.add_argument("--max-seconds", type=number_type(float), metavar="S", help="wall-clock budget per model")
    group.add_argument("--profile", choices=PROFILES, default="cpu",
                       help="training settings: cpu (lr 1e-3, Transformer 3e-4, batch 64, log1p + z-score) or denali "
                            "(its per-model lr, batch, epochs, preprocessing) (default: cpu)")
    group.add_argument("--keep-repeats", action="store_true", help="train on every repeat instead of their mean")


def training_options(args) -> dict:
    """The parsed :func:`add_training_options`, with --small's defaults: keywords of ``run_benchmark``."""
    epochs, width = args.epochs, args.width
    if args.small:
        epochs = SMALL["epochs"] if epochs is None else epochs
        width = SMALL["width"] if width is None else width
    return {"epochs": epochs, "width": DEFAULT_WIDTH if width is None else width,
            "patience": None if args.patience == 0 else args.patience, "average_repeats": not args.keep_repeats,
            "profile": args.profile, "max_seconds": args.max_seconds}


def add(sub) -> None:
    """The ``benchmark`` subcommand."""
    p = sub_parser(sub, "benchmark", "benchmark", "train and test the four DENALI models on the three tasks; "
                   "print the paper's table", description=BENCHMARK_DESCRIPTION)
    p.add_argument("--store", required=True, metavar="PATH", help="capture store (SQLite file)")
    p.add_argument("--where", metavar="COL=V,...", help="filter captures, e.g. lights=off,zones=3x3 "
                                                         "(alternatives with |, quoted: 'object=A|S')")
    p.add_argument("--models", type=names_type("model(s)", MODEL_NAMES), default=list(MODEL_NAMES), metavar="M,M",
                   help=f"models (default: {','.join(MODEL_NAMES)})")
    p.add_argument("--tasks", type=names_type("task(s)", TASKS), default=list(TASKS), metavar="T,T",
                   help=f"tasks (default: {','.join(TASKS)})")
    p.add_argument("--split", choices=SPLITS, default="random", help="train/test split (default: random)")
    add_training_options(p)
    p.add_argument("--seed", type=int, default=42, help="seed of the split and training (default: 42)")
    p.add_argument("--threads", type=number_type(int), metavar="N", help="torch CPU threads (default: torch's)")
    p.add_argument("--save-models", action="store_true", help="also write each model's checkpoint to OUT/models/{model}_{task}.pt")
    p.add_argument("--out", default=DEFAULT_OUT, metavar="DIR", help="output folder (default: %(default)s)")
    p.add_argument("--json", action="store_true", help="print the whole result as JSON")
    p.set_defaults(func=_cmd_benchmark)
