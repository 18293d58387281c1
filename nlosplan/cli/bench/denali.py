"""``nlosplan bench denali``: DENALI's benchmark protocol, exactly, on captures simulated for a sensor."""

from __future__ import annotations

import argparse

from nlosplan.cli.common import emit, int_type, names_type, note, progress_bar, seed_list_type, warn

EXAMPLES = (
    "nlosplan bench denali                              # quick budget on the CPU, full on a GPU",
    "nlosplan bench denali --device cuda --budget full --json > denali-full.json",
    "nlosplan bench denali --sensor tmf8828-3x3-short --models cnn1d --tasks loc,size --no-validation",
    "nlosplan bench denali --budget full --models knn        # DENALI's protocol, training-free, minutes on a CPU",
    "nlosplan bench denali --objects A,S,circle --positions 0-19 --epochs 5   # a small custom run",
    "nlosplan bench denali --budget full --models cnn1d --tasks loc --no-validation --seeds 42,43,44"
    "   # the recipe's own spread",
)

DESCRIPTION = """\
DENALI's benchmark protocol (github.com/NikhilBehari/denali, benchmark/main_table), exactly, on captures the
product simulates for a sensor, printed beside DENALI's Table 1 (the same networks trained on DENALI's real
captures). A simulated world is as hard as the real one when these agree.

Captures: DENALI's protocol, simulated for --sensor with its calibrated scene (30 objects x 2 sizes x 100
positions x lights on and off x 3 repeats = 36,000, each repeat a sample), kept in a capture store (default:
a file under the cache folder named by the sensor, scene, protocol and simulator source; a second run reuses
it, an interrupted build resumes). Cells: DENALI's MLP and 1D CNN for localization (RMSE, x and y errors
pooled), shape (30-way top-1) and size (4 in / 8 in accuracy): DENALI's models, preprocessing (raw counts;
the shape MLP log1p + one z-score), Adam settings, epochs, batch sizes, 70/30 split (seed 42, stratified for
classes) and metrics; a CPU run follows DENALI's code draw for draw.

Columns: predicted = the epoch with the best test score, as DENALI reports (optimistic: it looks at the test
set); last epoch = the recipe's last epoch (test-blind); validation-chosen = a second training on the
training rows minus a seeded tenth, its epoch chosen on that tenth, scored on the test set (test-blind;
90 % of the training rows; --no-validation skips it and halves the time); real = DENALI's Table 1.

Seeds: DENALI trains each cell once, with torch seeded at 42; its figure is one draw of the recipe. --seeds
42,43,44 trains every cell once per seed (the split stays DENALI's) and prints each seed's row and the spread
(mean, standard deviation, lowest and highest, whether the real figure lies between): how far one run's figure
can be trusted, before comparing it with Table 1. Time grows with the number of seeds.

Budgets: full = DENALI's protocol (about two minutes per 1D CNN cell on a datacenter GPU; on 2 idle CPU cores
8-14 min per 1D CNN cell, 60-100 epochs, twice that with the validation run: a warning with the estimate for this
machine comes first);
quick = every fifth position (7,200 captures) and a fifth of DENALI's epochs: not DENALI's numbers, a look
at the trend in minutes, and the output says so. Default: full on a GPU, quick on the CPU. --objects,
--positions and --epochs narrow the protocol further (budget "custom").

JSON: {"rows": [{"task", "model", "metric", "predicted", "predicted_last_epoch",
"predicted_validation_epoch", "real", "budget", "device", "seconds", "best_epoch", "epochs",
"validation_epoch", "n_train", "n_test", "predicted_by_lights", "seed"}...], "spread": [{"task", "model",
"metric", "seeds", "predicted", "mean", "sd", "min", "max", "predicted_last_epoch", "real", "real_in_range"}...]
(two seeds or more), "seeds", "cells": [per-run settings and per-epoch history...], "protocol", "captures",
"real_source", "device", "seconds"}."""


def _fmt(metric: str, value) -> str:
    if value is None:
        return "-"
    return f"{100 * value:.2f} cm" if metric == "loc_rmse" else f"{100 * value:.2f} %"


def _text(res: dict, sensor: str) -> str:
    from nlosplan.reports.tables import format_table
    from nlosplan.simulators.presets.scene_model import describe_scene_options

    p = res["protocol"]
    head = [f"DENALI's benchmark (its recipe, exactly) on captures simulated for {sensor} "
            f"({describe_scene_options(res['captures']['scene_options'])}):",
            f"  {p['description']}; budget {p['budget']}; store {res['captures']['store']}"]
    if p["budget"] != "full":
        head.append("  NOT DENALI's protocol (fewer captures or epochs): a look at the trend, not its numbers; "
                    "--budget full for those")
    rows = [{"task": r["task"], "model": r["model"], "metric": r["metric"],
             "predicted (best on test)": _fmt(r["metric"], r["predicted"]),
             "last epoch": _fmt(r["metric"], r["predicted_last_epoch"]),
             "validation-chosen": _fmt(r["metric"], r["predicted_validation_epoch"]),
             "real": _fmt(r["metric"], r["real"]),
             "lights on / off": " / ".join(_fmt(r["metric"], r["predicted_by_lights"].get(k)) for k in ("on", "off")),
             "budget": r["budget"], "device": r["device"], "seconds": round(r["seconds"])} for r in res["rows"]]
    several = len(res.get("seeds", ())) > 1
    if several:
        rows = [{**row, "seed": "-" if r["seed"] is None else r["seed"]} for row, r in zip(rows, res["rows"])]
    foot = ("predicted: the epoch with the best test score (DENALI's choice); last epoch: the recipe's last; "
            "validation-chosen: " + ("a second run on 90 % of the training rows, its epoch chosen on the other "
                                     "10 %" if res["validation"] else "not run (--no-validation)") +
            "; real: DENALI's Table 1 on real captures."
            + ("\nknn: k nearest neighbours on principal components of square-root counts (no epochs; the components and k "
               "chosen on 15 % of the training rows): "
               "one test-blind figure in every column; Table 1 has no such learner." if any(
                   r["model"] == "knn" for r in res["rows"]) else "") + "\n"
            f"{res['seconds']:.0f} s on {res['device']} ({res['torch_threads']} torch threads), "
            f"torch {res['torch']}")
    spread = []
    if several and res["spread"]:
        spread = ["", "Over the training seeds (DENALI's figure, best on test, once per seed; "
                      "DENALI ran seed 42 once):",
                  format_table([{"task": g["task"], "model": g["model"], "seeds": len(g["seeds"]),
                                 "mean": _fmt(g["metric"], g["mean"]), "sd": _fmt(g["metric"], g["sd"]),
                                 "lowest - highest": f"{_fmt(g['metric'], g['min'])} - {_fmt(g['metric'], g['max'])}",
                                 "real": _fmt(g["metric"], g["real"]),
                                 "real between": "-" if g["real_in_range"] is None else
                                 ("yes" if g["real_in_range"] else "no")} for g in res["spread"]])]
    return "\n".join(head + [format_table(rows)] + spread + [foot])


def _check(args):
    """Every input, one line each, before any work: the device, budget, sensor, store. Returns (device, protocol)."""
    from nlosplan.files import check_free_space, check_output_file
    from nlosplan.sensor_models import resolve_sensor
    from nlosplan.tasks.denali_bench import protocol_for
    from nlosplan.tasks.denali_recipe import resolve_device

    device = resolve_device(args.device)
    budget = args.budget or ("full" if device.startswith("cuda") else "quick")
    protocol = protocol_for(budget, objects=args.objects, positions=args.positions, epochs=args.epochs)
    sensor = resolve_sensor(args.sensor)
    if args.store:
        check_output_file(args.store, "--store")
        check_free_space(args.store, protocol.n_captures * (8 * sensor.n_zones * sensor.n_bins + 600), "--store")
    return device, protocol


def _cmd(args) -> int:
    import torch

    from nlosplan.tasks.denali_bench import estimate_seconds, run_denali_bench

    device, protocol = _check(args)
    if args.threads is not None:
        torch.set_num_threads(args.threads)
    budget = args.budget or ("full" if device.startswith("cuda") else "quick")
    if device == "cpu":
        est = estimate_seconds(args.models, args.tasks, protocol, device, validation=not args.no_validation,
                               n_seeds=len(args.seeds))
        took = f"{est / 3600:.1f} h" if est >= 3600 else f"{max(1.0, est / 60):.0f} min"
        line = (f"bench denali: {protocol.describe()} on the CPU: about {took} of training on this machine now "
                "(timed on a few batches), plus the captures' simulation the first time")
        if protocol.budget == "full" and set(args.models) - {"knn"}:
            warn(line + "; DENALI's 1D CNN cells take 8-14 min each on 2 idle cores (more on a loaded machine) "
                        "and minutes on a GPU (--device cuda); --budget quick for a first look")
        else:
            note(args, line)
    with progress_bar(args, None, "bench denali", "step") as bar:
        res = run_denali_bench(args.sensor, budget=budget, models=args.models, tasks=args.tasks, device=device,
                               validation=not args.no_validation, store=args.store, objects=args.objects,
                               positions=args.positions, epochs=args.epochs, seeds=args.seeds, progress=bar)
    emit(args, res, _text(res, res["captures"]["sensor"]))
    return 0


def add_bench(bsub) -> None:
    """``nlosplan bench denali``."""
    from nlosplan.cli.selections import object_list, position_list
    from nlosplan.simulators.presets.scene_model import DEFAULT_SENSOR
    from nlosplan.tasks.names import TASKS

    p = bsub.add_parser("denali", help="DENALI's own benchmark recipe on simulated captures, predicted beside "
                                       "its real Table 1",
                        description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter,
                        epilog="examples:\n" + "\n".join(f"  {e}" for e in EXAMPLES))
    p.add_argument("--sensor", default=DEFAULT_SENSOR,
                   help="sensor preset or file whose captures are simulated (default: %(default)s, the tool's "
                        "default: DENALI's unit as calibrated)")
    p.add_argument("--device", default="auto", choices=["auto", "cpu", "cuda"],
                   help="where torch trains: auto = a CUDA GPU when torch sees one, else the CPU (default: auto)")
    p.add_argument("--budget", default=None, choices=["full", "quick"],
                   help="full = DENALI's protocol; quick = 7,200 captures and a fifth of the epochs (default: full "
                        "on a GPU, quick on the CPU)")
    p.add_argument("--store", default=None, metavar="PATH",
                   help="capture store to fill and reuse (default: a content-keyed file under the cache folder, "
                        "$NLOSPLAN_CACHE or ~/.cache/nlosplan, in denali-bench/)")
    p.add_argument("--models", type=names_type("model(s)", ("cnn1d", "mlp", "knn")), default=["cnn1d", "mlp"],
                   help="DENALI's cells to train: cnn1d, mlp (default: both); knn adds k nearest neighbours on "
                        "principal components of square-root counts (no epochs; their number and k chosen on a share "
                        "of the training rows: one test-blind "
                        "figure, about a minute per task at full budget on 2 CPU cores; not in Table 1)")
    p.add_argument("--tasks", type=names_type("task(s)", TASKS), default=list(TASKS),
                   help="loc, shape, size (default: all three)")
    p.add_argument("--no-validation", action="store_true",
                   help="skip the second training per cell that gives the validation-chosen epoch (halves the time)")
    p.add_argument("--objects", type=object_list, default=None, metavar="A,S,...",
                   help="only these objects (DENALI objects or class groups; budget becomes custom)")
    p.add_argument("--positions", type=position_list, default=None, metavar="0-99",
                   help="only these gantry positions (budget becomes custom)")
    p.add_argument("--epochs", type=int_type(1, 10000), default=None, metavar="N",
                   help="epochs for every cell instead of DENALI's (budget becomes custom)")
    p.add_argument("--seeds", type=seed_list_type(max_count=20), default=[42], metavar="S1,S2,...",
                   help="seeds of torch's generator; each 1D CNN and MLP cell is trained once per seed and the spread "
                        "printed (default: 42 alone, DENALI's; the split stays DENALI's)")
    p.add_argument("--threads", type=int_type(1, 256), default=None, metavar="N",
                   help="torch CPU threads (default: torch's; on a busy shared machine 1 trains several times faster "
                        "than 2)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=_cmd)


def checkpoints_text(part: dict) -> str:
    """The ``checkpoints`` part of ``bench real`` for a person: scores, BatchNorm input distances, real breakdown."""
    from nlosplan.reports.tables import format_table

    if part.get("skipped"):
        return f"DENALI's real-trained networks: skipped ({part['skipped']})"
    rows, bn_rows = [], []
    for c in part["checkpoints"]:
        rows.append({"network": c["name"], "task": c["task"], "metric": c["metric"],
                     "simulated": _fmt(c["metric"], c["simulated"]), "real": _fmt(c["metric"], c["real"]),
                     "sim / real": round(c["ratio"], 2), "chance": _fmt(c["metric"], c["chance"]),
                     "lights on / off": " / ".join(_fmt(c["metric"], c["by_lights"].get(k)) for k in ("on", "off")),
                     "most predicted": (f"{c['modal_prediction']} ({100 * c['modal_share']:.0f} %)"
                                        if "modal_prediction" in c else "")})
        for layer, s in c["bn"].items():
            bn_rows.append({"network": c["name"], "layer": layer, "median |z|": s["median_abs_z"],
                            "mean log var ratio": s["mean_log_var_ratio"],
                            "rms log var ratio": s["rms_log_var_ratio"]})
    lines = [f"DENALI's real-trained networks on simulated captures ({part['protocol']['description']}; scored on "
             f"{part['rows_scored']}; {part['seconds']:.0f} s):", format_table(rows), "",
             "their BatchNorm inputs, simulated against the real running statistics (per channel z = (mean - "
             "running mean) / running sd, log(var / running var)):", format_table(bn_rows, floatfmt="{:.3g}")]
    bd = part.get("real_breakdown") or {}
    for name, b in bd.items():
        def acc(d):
            return ", ".join(f"{k} {100 * v:.1f} %" for k, v in d.items())
        lines.append(f"\n{name} on DENALI's REAL test split ({b['n']} captures, {100 * b['accuracy']:.2f} %): "
                     f"lights {acc(b['by_lights'])}; size {acc(b['by_size'])}; half {acc(b['by_half'])}; "
                     f"quadrant {acc(b['by_quadrant'])}; folder purity: median {100 * b['purity']['median_modal_share']:.1f} % "
                     f"of a folder's captures get its most frequent class, wrong in "
                     f"{100 * b['purity']['wrong_modal_share']:.1f} % of the {b['purity']['folders']} folders")
    return "\n".join(lines)


def inversion_text(part: dict) -> str:
    """The ``inversion`` part of ``bench real`` for a person: the fitted mean capture against the model's."""
    from nlosplan.reports.tables import format_table

    if part.get("skipped"):
        return f"The mean real capture behind DENALI's networks: skipped ({part['skipped']})"
    before = {(r["network"], r["layer"]): r for r in part["bn_before"]}
    bn_rows = [{"network": r["network"], "layer": r["layer"],
                "median |z| before -> after": f"{before[(r['network'], r['layer'])]['median_abs_z']:.2f} -> "
                                              f"{r['median_abs_z']:.2f}",
                "mean log var ratio before -> after": f"{before[(r['network'], r['layer'])]['mean_log_var_ratio']:+.2f}"
                                                      f" -> {r['mean_log_var_ratio']:+.2f}"} for r in part["bn_after"]]
    centre_m, centre_r = part["zones_model"][4]["peak_bin"], part["zones_real"][4]["peak_bin"]
    zone_rows = [{"zone (row, col)": f"({z // 3}, {z % 3})",
                  "direct peak vs centre, model": f"{m['peak_bin'] - centre_m:+d} bins",
                  "direct peak vs centre, fitted real": f"{r['peak_bin'] - centre_r:+d} bins",
                  "mean count, model": round(m["mean"]), "mean count, fitted real": round(r["mean"])}
                 for z, (m, r) in enumerate(zip(part["zones_model"], part["zones_real"]))]
    score_rows = [{"network": c["name"], "metric": c["metric"], "on moved captures": _fmt(c["metric"], c["simulated"]),
                   "real": _fmt(c["metric"], c["real"]), "chance": _fmt(c["metric"], c["chance"])}
                  for c in part["scores"]]
    return "\n".join([
        f"The mean real capture behind DENALI's networks: fitted to their BatchNorm running statistics "
        f"({len({r['network'] for r in part['bn_after']})} networks, {part['captures']} simulated captures' variation, "
        f"{part['iterations']} L-BFGS steps; {part['seconds']:.0f} s):", format_table(bn_rows), "",
        "per zone (identified: the zones' relative timing, to about 2 bins, and which are brighter; not the "
        "absolute time, the widths or the floor's share):", format_table(zone_rows), "",
        "the networks on the simulated captures moved to the fitted mean (x - model mean + fitted mean):",
        format_table(score_rows)])
