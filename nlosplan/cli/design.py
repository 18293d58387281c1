"""``nlosplan design``: the least hardware that does each NLOS task (the main job)."""

from __future__ import annotations

import argparse

from nlosplan.cli.common import emit, int_type, progress_bar, sub_parser
from nlosplan.errors import UserError
from nlosplan.resources import MAX_DESIGN_SEED, MAX_TRAIN_CAPTURES
from nlosplan.simulators import BACKENDS

DEFAULT_OUT = "nlosplan-out/design"

DESCRIPTION = """\
Find the least sensor hardware (zones, bin width, bins, timing jitter, pulse width,
photon budget) that does each NLOS task on the DENALI rig, and write a report.

With no options: the DENALI rig and DENALI's TMF8828 as calibrated on the real Table 2
(denali-tmf8828-3x3 as the reference, with the scene it was fitted with: retro albedo
0.37, a diffuse base of 0.2, the mount in the signal; its real floor of ~10^3 counts
per bin; [space] reference in --config picks another sensor), the three
tasks with the default requirements (localization RMSE <= 0.05 m, shape top-1 >= 0.35,
size accuracy >= 0.90), the default design space (zones 1x1..8x8, bins merged up to 8x,
32-128 bins, jitter and pulse 0-1000 ps, 1-100 % of the photons). 5 to 16 minutes the
first time on an idle 2-core machine, by its speed (1.5 to 4 of them simulating the references,
compiling and checking the simulator's stability; the learners, the worlds' references and the
optimizer on the bounds are most of the rest); --quick runs a reduced space (1 to 2.5 minutes
the first time, 0.5 to 1.5 after).
References are cached by content: a second run with
the same sensor model and scenes does not simulate them again.

Metrics: loc_rmse is DENALI's localization RMSE, metres: sqrt of the mean of the squared
x and y errors pooled over the N x 2 entries (loc<=X means loc_rmse <= X); top1_acc is
the top-1 accuracy of the shape or size class.

How: designs are emulated from simulated references (one per zone layout) by degrading
histograms (jitter, bin merging, truncation, photon scaling). Fast bounds (Cramer-Rao
bound, ideal observer) screen the space; the best learner of each task (--models: MLP,
1D CNN and k nearest neighbours by default, compared on the reference design) trained on
captures of a design verifies it; nlopt (COBYLA) looks for the cheapest design of every zone layout
and bin width with the bound corrected by the measured bound-to-trained gap.

A verdict is about the sensor and a learner with a training budget: "met with an MLP
trained on 2,100 captures". --train-captures N sets the budget (training captures per
learner at a design; default one per training scene: 2,100 in the main job, 700 with
--quick), --models the learner family; both are in result.json, the report and the summary.
At the reference design the learner is also trained along a ladder of budgets (a quarter
and half of the run's, four times it, and DENALI's 25,200 captures; 2 seeds each, 1 with
--quick; [search] curve_seeds): its learning curve, every point trained, none extrapolated.

Verdicts are met (the pessimistic end of the 95 % interval meets the requirement), not
met (even the optimistic end fails) or undecided (it straddles). A run of a design at
a seed draws new Poisson noise, a new train/test split and a new training seed; the
interval of a design is that of its mean over its runs, so two runs with different
--seed give the same verdicts within their intervals. Undecided candidates get more
seeds until decided or the budget is spent. The cheapest met candidates are then
checked in --worlds plausible worlds (object albedo, background, photon scale, extra
jitter, and a calibration's parameter uncertainty when the sensor has one): the
minimum hardware is the cheapest design met in at least 90 % of them (undecided worlds
get more seeds from the worlds' own budget, [worlds] budget, where a seed can change
the answer). With --real, the trained evaluator uses real captures from a store instead
(designs finer than the captures are reported unreachable; no worlds).

First the answer at DENALI's own design point (3x3, 128 bins of 92.8 ps, no added
jitter, all photons): each task's predicted metric with its interval, learner and
training captures (DENALI's 25,200, as Table 1 trained on, where the learning curve
reaches them; the run's own budget beside it), its bound, and DENALI's real Table 1
figure (1D CNN on 25,200 real captures: 4.56 cm, 38.8 %, 94.7 %) with both verdicts and
whether they agree; a
sentence where they disagree, and beside an answer that needs more hardware than
DENALI's although DENALI meets the requirement in reality. A learner that beats its
bound (Cramer-Rao, ideal observer) beyond its interval is flagged.

Output (OUT): report.html (self-contained), report.md, PNG plots, result.json,
design_checkpoint.json and design_evaluations.jsonl (every evaluation; --resume
continues from them; a rerun into a folder with a previous run needs --resume or
--overwrite). Progress goes to stderr, also with --json.
JSON: {"train_captures": {"requested", "default", "rule", "learner", "models", "epochs",
"captures"}, "denali_point": [{"task", "metric", "requirement", "predicted", "interval",
"evaluator", "learner", "train_captures", "bound", "real", "real_source", "verdict",
"real_verdict", "agrees", "answer_note", "run_budget", "learning_curve": [{"train_captures",
"value", "lo", "hi", "seeds", "verdict", "run_budget"}...], "conservative"}...], "consistency": [{"task", "design",
"learner", "value", "bound", "issue"}...], "cheapest": [{"requirement", "verdict",
"design", "value", "lo", "hi", "worlds"}...], "requirements": [{"task", "parameter",
"minimum" or "maximum", "interval", "verdict", "feasible"}...], "learners": [...],
"metric_definitions": {...}, "report": PATH}; loc_rmse in metres."""


def requirement_type(text: str):
    from nlosplan.planner.design.requirements import parse_requirement

    try:
        return parse_requirement(text)
    except UserError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _cluster(text: str) -> str:
    """``tcp://HOST:PORT`` or ``local:N`` (checked before any work starts)."""
    if text.startswith("tcp://") and ":" in text[6:]:
        return text
    if text.startswith("local:") and text[6:].isascii() and text[6:].isdigit() and int(text[6:]) >= 1:
        return text
    raise argparse.ArgumentTypeError(f"{text!r}: give tcp://HOST:PORT (a running Dask scheduler) or local:N (N >= 1)")


def _models(text: str) -> tuple[str, ...]:
    """``mlp,cnn1d`` -> the candidate learners (checked before any work starts)."""
    from nlosplan.tasks.names import LEARNER_NAMES, check_names

    try:
        return tuple(check_names("model(s)", [m.strip() for m in text.split(",") if m.strip()], LEARNER_NAMES))
    except UserError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def build_config(args):
    """The :class:`DesignConfig` of the parsed options."""
    from dataclasses import replace

    from nlosplan.planner.design.config import full_config, load_config, quick_config

    cfg = quick_config() if args.quick else full_config()
    if args.config:
        cfg = load_config(args.config, cfg)
    if args.requirement:
        cfg = replace(cfg, requirements=tuple(args.requirement))
    if args.backend != "fast":
        cfg = replace(cfg, scenes=replace(cfg.scenes, backend=args.backend))
    if args.seeds is not None:
        cfg = replace(cfg, search=replace(cfg.search, seeds=args.seeds,
                                          max_seeds=max(cfg.search.max_seeds, args.seeds)))
    if args.seed is not None:
        cfg = replace(cfg, search=replace(cfg.search, seed=args.seed))
    if args.models is not None:
        cfg = replace(cfg, search=replace(cfg.search, models=args.models))
    if args.train_captures is not None:
        from nlosplan.planner.design.budget import TRAIN_CAPTURES

        fid = {k: dict(v) for k, v in cfg.search.fidelity.items()}
        fid["trained"][TRAIN_CAPTURES] = args.train_captures
        cfg = replace(cfg, search=replace(cfg.search, fidelity=fid))
    if args.worlds is not None:
        cfg = replace(cfg, worlds=replace(cfg.worlds, count=args.worlds))
    for flag, value in (("--where", args.where), ("--capture-sensor", args.capture_sensor)):
        if value is not None and not args.real:
            raise UserError(f"{flag} applies only with --real STORE (the real captures it describes)")
    if args.real:
        where = None
        if args.where:
            from nlosplan.cli.common import parse_where

            where = parse_where(args.where)
        cfg = replace(cfg, real=args.real, real_where=where, capture_sensor=args.capture_sensor)
    return cfg


def _cmd_design(args) -> int:
    from pathlib import Path

    from nlosplan.cli.live import live_page
    from nlosplan.files import check_output_dir, write_json, writing
    from nlosplan.planner.design.run import run_design
    from nlosplan.reports.design_report import minimum_hardware_text, write_design_report

    if args.repair and not args.resume:
        raise UserError("--repair applies only with --resume")
    if args.overwrite and args.resume:
        raise UserError("--overwrite and --resume exclude each other: continue the run or start over")
    cfg = build_config(args)
    check_output_dir(args.out)
    with live_page(args, "design", args.out), progress_bar(args, None, "design", "evaluation") as bar:
        def progress(text, done, total):
            stage, _, detail = text.partition(": ")
            if stage in ("checkpoint",):
                bar.note(detail)
                return
            bar.stage(stage, unit="reference" if stage.endswith("references") else "evaluation")
            if done is not None:
                bar.set(done, total, detail)
            else:
                bar.set_postfix_str(detail)

        result = run_design(cfg, args.out, resume=args.resume, workers=args.workers, cluster=args.cluster,
                            progress=progress, overwrite=args.overwrite, repair=args.repair,
                            cache=not args.no_cache)
    with writing(kept=f"every evaluation is kept in {args.out} (design_evaluations.jsonl)",
                 cont="free some space and rerun with --resume: nothing is evaluated again"):
        paths = write_design_report(result, args.out)
        result["report"] = paths["html"]
        result["report_markdown"] = paths["markdown"]
        write_json(Path(args.out, "result.json"), result, default=str, indent=1)
    short = {"denali_point": result["denali_point"], "consistency": result["consistency"],
             "cheapest": result["cheapest"],
             "requirements": [{k: r[k] for k in ("task", "requirement", "parameter", "unit", "minimum", "maximum",
                                                 "interval", "verdict", "feasible", "note") if k in r}
                              for r in result["requirements"]],
             "learners": [r for r in result["learners"] if r["chosen"]], "train_captures": result["train_captures"],
             "worlds": None if result["worlds"] is None else {k: result["worlds"][k] for k in
                                                              ("count", "quorum", "needed", "sources")},
             "world_model": result.get("world_model"),
             "metric_definitions": result["metric_definitions"], "seed": result["provenance"]["seed"],
             "report": paths["html"], "wall_seconds": result["provenance"]["wall_seconds"],
             "evaluations": result["evaluations"]}
    text = (minimum_hardware_text(result, result["reference_bin_ps"])
            + f"\n\n{result['evaluations']} evaluations in {result['provenance']['wall_seconds']:.0f} s; "
              f"report: {paths['html']} (also report.md)")
    emit(args, short, text)
    return 0


def add(sub) -> None:
    """The ``design`` subcommand."""
    p = sub_parser(sub, "design", "design",
                   "the least hardware per NLOS task on the DENALI rig: search, verify, report (the main job)",
                   description=DESCRIPTION)
    p.add_argument("--quick", action="store_true",
                   help="reduced space and scenes (zones 1x1/3x3, four axes, 10 objects, 4 worlds): 1 to 2.5 minutes "
                        "the first time, 0.5 to 1.5 after")
    p.add_argument("--config", metavar="TOML", help="design space, requirements, cost, search and scenes "
                                                     "(see nlosplan/planner/design/config.py for the tables)")
    p.add_argument("--requirement", action="append", type=requirement_type, metavar="REQ",
                   help="a requirement, repeatable, e.g. loc<=0.03, shape>=0.5, size>=0.9@lights=on "
                        "(replaces the defaults)")
    p.add_argument("--backend", choices=tuple(BACKENDS), default="fast",
                   help="simulator of the reference histograms: the fast JAX backend (default) or the Mitsuba 3 twin "
                        "(about 0.1 s per scene: the full run's 15,000 scenes take ~30 min; bounds' Jacobians stay fast)")
    p.add_argument("--seeds", type=int_type(1, 20), default=None,
                   help="seeds of the verification (default 3, also with --quick)")
    p.add_argument("--seed", type=int_type(0, MAX_DESIGN_SEED), default=None,
                   help=f"the run's seed, 0 to {MAX_DESIGN_SEED} (default 0): Poisson noise, train/test splits, training "
                        "seeds and the worlds are drawn from it")
    p.add_argument("--models", type=_models, default=None, metavar="M1,M2",
                   help="candidate learners, compared on the reference design; the best per task is used "
                        "(default mlp,cnn1d,knn: DENALI's MLP and 1D CNN as the benchmark trains them, and k nearest "
                        "neighbours on principal components of square-root counts, their number and k chosen on a "
                        "validation part; also cnn3d, transformer)")
    p.add_argument("--train-captures", type=int_type(2, MAX_TRAIN_CAPTURES), default=None, metavar="N",
                   help="training captures each learner gets at a design (the training budget; a verdict is 'met "
                        "with a 1D CNN trained on N captures'). Default: one per training scene (70 %% of the "
                        "scenes: 2,100 for the main job's 3,000, 700 with --quick; the worlds' learners, on every "
                        "2nd position, half that; with --real every real capture of the training scenes). Fewer: "
                        "a seeded subset; more: further noisy captures of the training scenes are drawn (DENALI "
                        "trained on 25,200: hours on 2 cores). With --real at most what the store's training side "
                        f"holds. 2 to {MAX_TRAIN_CAPTURES:,}; a resume needs the same N")
    p.add_argument("--worlds", type=int_type(1, 64), default=None, metavar="K",
                   help="plausible worlds the cheapest met designs are checked in (default 8; quick 4)")
    p.add_argument("--out", default=DEFAULT_OUT, metavar="DIR", help="output folder (default: %(default)s)")
    p.add_argument("--resume", action="store_true",
                   help="continue from OUT/design_checkpoint.json; nothing evaluated is computed again (an error "
                        "when OUT holds no run)")
    p.add_argument("--repair", action="store_true",
                   help="with --resume: drop damaged lines of OUT/design_evaluations.jsonl (they are named; their "
                        "evaluations run again; the damaged file is kept as .damaged)")
    p.add_argument("--overwrite", action="store_true",
                   help="start over where OUT holds a previous run (its files move to .bak); without it that is "
                        "an error")
    p.add_argument("--no-cache", action="store_true",
                   help="simulate the references even when an earlier run with the same sensor, scenes and "
                        "simulator code left them in the cache ($NLOSPLAN_CACHE or ~/.cache/nlosplan), and run "
                        "the stability catalog even when this code's result is kept there")
    runner = p.add_argument_group("where evaluations run")
    runner.add_argument("--workers", type=int_type(1, 256), default=None,
                        help="local worker processes (default: the CPU count)")
    runner.add_argument("--cluster", metavar="ADDR", type=_cluster,
                        help="a Dask cluster: tcp://HOST:PORT (workers must see OUT) or local:N to start one here")
    real = p.add_argument_group("real captures (optional)")
    real.add_argument("--real", metavar="STORE", help="capture store (SQLite) whose captures the trained evaluator "
                                                      "uses (import a DENALI folder with 'nlosplan dataset import-denali')")
    real.add_argument("--where", metavar="COL=V,...", help="filter of the real captures, e.g. lights=off")
    real.add_argument("--capture-sensor", metavar="NAME|FILE", help="preset or sensor file of the real captures "
                                                                    "(default: the space's reference)")
    p.add_argument("--json", action="store_true", help="print the JSON summary (see above)")
    from nlosplan.cli.live import add_live_option

    add_live_option(p, "the run (stage, progress, the answer so far, trade-off plots)")
    p.set_defaults(func=_cmd_design)


__all__ = ["add", "build_config"]
