"""``nlosplan study``: declarative studies (``jitter``: DENALI's timing-jitter study)."""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

from nlosplan.cli.benchmark import add_training_options, training_options
from nlosplan.cli.study import active as active_study, design as design_studies
from nlosplan.cli.common import (command_group, emit, names_type, note, number_type, parse_where, progress_bar,
                                 seed_type, sub_parser)
from nlosplan.errors import UserError
from nlosplan.schema import parse_number
from nlosplan.experiments.jitter import DEFAULT_JITTER_PS, DEFAULT_MODELS, STUDY_ZONES
from nlosplan.tasks.names import DEFAULT_EPOCHS, MODEL_NAMES, SPLITS, TASKS

DEFAULT_OUT = "nlosplan-out/jitter"
#: torch threads: the one-zone models are tiny; on a shared 2-core VM, 2 threads took 264 s where 1 took 7 s.
DEFAULT_THREADS = 1


def _jitter_levels(text: str) -> list[float]:
    """An argparse type: comma-separated jitter FWHMs in ps, each finite and >= 0."""
    values = []
    for item in (v.strip() for v in text.split(",")):
        if not item:
            continue
        try:
            value = parse_number(item.removesuffix("ps").strip())
        except ValueError:
            raise argparse.ArgumentTypeError(f"{item!r} is not a number (jitter FWHM in ps)") from None
        if not (math.isfinite(value) and value >= 0):
            raise argparse.ArgumentTypeError(f"jitter {item} ps is not allowed; FWHMs must be finite and >= 0 ps")
        values.append(value)
    if not values:
        raise argparse.ArgumentTypeError("give at least one jitter FWHM in ps, e.g. 0,50,100,600")
    return values


def _reporter(args):
    """Progress lines on stderr (one per level and per finished model and task), unless --quiet."""
    if args.quiet:
        return None
    started: dict[tuple[str, str], float] = {}

    def progress(event: dict) -> None:
        kind = event["event"]
        head = f"[jitter {event['jitter_ps']:g} ps, level {event['level'] + 1}/{event['levels']}]"
        if kind == "level":
            s = event["summary"]
            line = (f"{head} {len(event['dataset'])} captures, {args.zone} zone"
                    f"{'' if args.zone == 'centre' else 's'}: mean highest bin {s['peak_counts']:.4g} counts, "
                    f"direct peak {s['peak_width_ps']:.0f} ps wide at half maximum")
        elif kind == "start":
            started[(event["model"], event["task"])] = time.perf_counter()
            return
        elif kind == "done":
            t0 = started.pop((event["model"], event["task"]), None)
            took = "n/a for this split" if t0 is None else f"trained and tested in {time.perf_counter() - t0:.1f} s"
            line = f"{head} {event['model']} {event['task']} ({event['index'] + 1}/{event['total']}): {took}"
        elif kind == "level_done":
            line = f"{head} done in {event['seconds']:.1f} s"
        else:
            return
        print(line, file=sys.stderr, flush=True)

    return progress


def _import_denali(args, store: Path) -> None:
    from nlosplan.data.denali_io import import_denali

    note(args, f"importing DENALI folder {args.denali} into {store} (resumable) ...")
    with progress_bar(args, None, "import DENALI", "file") as bar:
        res = import_denali(args.denali, store, trust_pickle=args.trust_pickle,
                            progress=lambda done, total, text: bar.set(done, total, text))
    if not args.quiet:
        print(f"imported {res['captures_added']} captures ({res['captures_skipped']} stored already) from "
              f"{res['files']} files of {args.denali} into {store} in {res['seconds']:.1f} s",
              file=sys.stderr, flush=True)


def _cmd_jitter(args) -> int:
    import torch

    from nlosplan.experiments.jitter import JitterStudy, load_study_dataset, run_jitter_study
    from nlosplan.files import check_output_dir, check_output_file, check_plot_path, writing
    from nlosplan.reports.jitter_plot import jitter_text, write_jitter

    if args.store is None and args.denali is None:
        raise UserError("study jitter needs data: give --store PATH (a capture store) or --denali DIR "
                        "(a real DENALI data folder to import)")
    if args.trust_pickle and args.denali is None:
        raise UserError("--trust-pickle only applies with --denali DIR")
    study = JitterStudy(jitter_ps=tuple(args.jitter_ps), models=tuple(args.models), tasks=tuple(args.tasks),
                        zone=args.zone, split=args.split, seed=args.seed, **training_options(args))
    where = parse_where(args.where)
    check_output_dir(args.out)
    if args.plot is not None:
        check_plot_path(args.plot)
    store = Path(args.store) if args.store is not None else Path(args.out) / "denali.sqlite"
    if args.denali is not None:
        check_output_file(store, "--store" if args.store is not None else "--out")
    torch.set_num_threads(args.threads)
    if args.denali is not None:
        _import_denali(args, store)
    note(args, f"loading {store} ({', '.join(f'{k}={v}' for k, v in where.items()) or f'zones={STUDY_ZONES}'}) ...")
    dataset = load_study_dataset(store, where)
    result = run_jitter_study(dataset, study, progress=_reporter(args))
    result["config"]["store"] = str(store)
    result["config"]["where"] = where
    result["config"]["denali"] = None if args.denali is None else str(args.denali)
    with writing(cont="free some space or choose another --out and rerun"):
        files = write_jitter(result, args.out, plot=args.plot)
    result["files"] = files
    emit(args, result, jitter_text(result) + "\n\n" + "\n".join(f"wrote {k}: {v}" for k, v in files.items()))
    return 0


JITTER_DESCRIPTION = f"""\
DENALI's timing-jitter study. Only the centre zone of the 3x3 sensor is used
(one histogram per scene: the models must read the object from timing
alone). Every capture is blurred by Gaussian timing jitter of FWHM J ps
(exact re-binning through the Gaussian; default J = 0, 50, 100, 600) for
training AND for testing, then each scene's repeats are averaged and the
benchmark models are trained and tested on the three tasks at every level:
localization (RMSE, MAE in m; DENALI's loc_rmse, x and y errors pooled),
30-way shape (top-1, top-5, macro F1) and 4 in vs 8 in size (accuracy,
precision, recall). The split depends only on
the labels and --seed, so every level trains and tests on the same scenes.

Data: the captures of --store that match --where (zones={STUDY_ZONES} unless
--where names another odd grid; DENALI's background captures are left out),
or a real DENALI folder given with --denali DIR, imported (resumably) into
--store, or into OUT/denali.sqlite without --store.

Writes into --out: jitter.csv (a row per jitter level, model/task/metric
columns, overall values in m and fractions, plus each level's histogram
peak and seconds), jitter.md (the tables and the figure), jitter.json (every
row and breakdown, per-level timings and all settings) and jitter.png (a
panel per task, a line per model, chance levels dashed; --plot moves it).
Progress lines go to stderr (--quiet silences them).

Cost: levels x models x tasks trainings (4 x 2 x 3 = 24 by default), each
like one 'nlosplan benchmark' entry on a single zone, plus under 2 s to
blur the captures. Measured on 2 CPU cores, 1 torch thread (the default),
1,200 simulated scenes (30 objects x 2 sizes x 20 positions, 3 repeats):
--small 7 s, the defaults (--epochs {DEFAULT_EPOCHS}, early stopping) 33 s. The 3D CNN
costs about as much as the 1D CNN; the Transformer about 13 s per epoch and
task (--small: 3 min per level, 13 min for the four levels). Time grows
about linearly with the scenes (DENALI's 6,000: about 5x). More threads
do not help these small models and can be far slower on a busy machine
(264 s instead of 7 s with --threads 2)."""


def add(sub) -> None:
    """The ``study`` subcommand: ``jitter`` here, then ``resolution``/``bins`` (:mod:`.design`) and ``active-vs-raster`` (:mod:`.active`)."""
    ssub = command_group(sub, "study", "declarative studies (jitter, resolution, bins, active-vs-raster)",
                         "Declarative studies: a small configuration of what to vary, run through the benchmark models, "
                         "the design planner or the capture planner, written as tables, JSON and a figure.",
                         metavar="STUDY")
    p = sub_parser(ssub, "jitter", "study jitter",
                   "DENALI's timing-jitter study: centre zone, Gaussian jitter at training and test, three tasks",
                   description=JITTER_DESCRIPTION)
    data = p.add_argument_group("data")
    data.add_argument("--store", metavar="PATH", help="capture store (SQLite file); with --denali, the import target")
    data.add_argument("--where", metavar="COL=V,...", help="filter captures, e.g. lights=off "
                                                            "(alternatives with |, quoted: 'object=A|S')")
    data.add_argument("--denali", metavar="DIR", help="a real DENALI data folder (<obj>_<4inch|8inch>_<3x3|8x8>_"
                                                      "<lighton|lightoff>_NLOSdata) to import and study")
    data.add_argument("--trust-pickle", action="store_true",
                      help="with --denali: allow capture files that need pickle (they may run code): trusted data only")
    design = p.add_argument_group("study")
    design.add_argument("--jitter-ps", type=_jitter_levels, default=list(DEFAULT_JITTER_PS), metavar="J,J",
                        help=f"jitter FWHMs in ps, sorted and without duplicates "
                             f"(default: {','.join(f'{v:g}' for v in DEFAULT_JITTER_PS)})")
    design.add_argument("--models", type=names_type("model(s)", MODEL_NAMES), default=list(DEFAULT_MODELS), metavar="M,M",
                        help=f"models among {','.join(MODEL_NAMES)} (default: {','.join(DEFAULT_MODELS)}; one zone "
                             "leaves the 3D CNN nothing spatial, the Transformer is the slowest)")
    design.add_argument("--tasks", type=names_type("task(s)", TASKS), default=list(TASKS), metavar="T,T",
                        help=f"tasks (default: {','.join(TASKS)})")
    design.add_argument("--zone", choices=("centre", "all"), default="centre",
                        help="centre zone only (DENALI) or every zone, for comparison (default: centre)")
    design.add_argument("--split", choices=SPLITS, default="random", help="train/test split (default: random)")
    design.add_argument("--seed", type=seed_type(), default=42, help="seed of the split and training, 0 to 2**32-1 "
                                                                     "(default: 42)")
    train = p.add_argument_group("training (as 'nlosplan benchmark')")
    add_training_options(train)
    train.add_argument("--threads", type=number_type(int), default=DEFAULT_THREADS, metavar="N",
                       help="torch CPU threads (default: %(default)s: one-zone models are too small to gain from "
                            "more, and extra threads stall on a busy machine)")
    out = p.add_argument_group("output")
    out.add_argument("--out", default=DEFAULT_OUT, metavar="DIR", help="output folder (default: %(default)s)")
    out.add_argument("--plot", metavar="PATH", help="figure path (default: OUT/jitter.png)")
    out.add_argument("--json", action="store_true", help="print the whole result as JSON")
    out.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    p.set_defaults(func=_cmd_jitter)
    design_studies.add_study(ssub)
    active_study.add_study(ssub)
