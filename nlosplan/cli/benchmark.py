"""``nlosplan benchmark``: train and test the four models on the three DENALI tasks; print the paper's table."""

from __future__ import annotations

import time
from contextlib import contextmanager

from nlosplan.cli.common import emit, names_type, note, number_type, parse_where, progress_bar, seed_type, sub_parser
from nlosplan.tasks.names import (DEFAULT_EPOCHS, DEFAULT_PATIENCE, DEFAULT_WIDTH, MODEL_NAMES, PROFILES, SMALL,
                                  SPLITS, TASKS)

DEFAULT_OUT = "nlosplan-out/benchmark"

def _load_dataset(store: str, where: dict):
    """The captures of ``store`` that match ``where`` (a :class:`~nlosplan.data.dataset.Dataset`); read-only."""
    from nlosplan.data.load import load_dataset

    return load_dataset(store, where)


@contextmanager
def _progress(args, n_entries: int):
    """Progress over the (model, task) entries on stderr: a tqdm bar on a terminal, else a line every few seconds
    (the current model, task and epoch) and one per finished entry."""
    with progress_bar(args, n_entries, "benchmark", "model") as bar:
        started: dict = {}

        def update(event: dict) -> None:
            kind = event["event"]
            if kind == "start":
                started[(event["model"], event["task"])] = time.perf_counter()
                bar.set_postfix_str(f"{event['model']} {event['task']}")
            elif kind == "epoch":
                rec = event["record"]
                val = "" if rec["val_loss"] is None else f" val {rec['val_loss']:.3g}"
                bar.set_postfix_str(f"{event['model']} {event['task']} epoch {rec['epoch']}{val}")
            elif kind == "done":
                t0 = started.pop((event["model"], event["task"]), None)
                took = "" if t0 is None else f" in {time.perf_counter() - t0:.0f} s"
                bar.update(1, f"{event['model']} {event['task']} done{took}")

        yield update


def _cmd_benchmark(args) -> int:
    import torch

    from nlosplan.files import WriteFailed, check_output_dir
    from nlosplan.reports.benchmark_table import benchmark_text, write_benchmark
    from nlosplan.tasks.benchmark import run_benchmark

    check_output_dir(args.out)
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
    try:
        files = write_benchmark(result, args.out)
    except WriteFailed as exc:  # keep the work: print the table, then say what was not written
        emit(args, result, benchmark_text(result))
        raise WriteFailed(f"{exc}; the table is printed above, no file was left partial; free some space or choose "
                          "another --out and rerun") from None
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
    p.add_argument("--seed", type=seed_type(), default=42, help="seed of the split and training, 0 to 2**32-1 "
                                                                "(default: 42)")
    p.add_argument("--threads", type=number_type(int), metavar="N", help="torch CPU threads (default: torch's)")
    p.add_argument("--save-models", action="store_true", help="also write each model's checkpoint to OUT/models/{model}_{task}.pt")
    p.add_argument("--out", default=DEFAULT_OUT, metavar="DIR", help="output folder (default: %(default)s)")
    p.add_argument("--json", action="store_true", help="print the whole result as JSON")
    p.set_defaults(func=_cmd_benchmark)
