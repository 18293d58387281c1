"""``nlosplan rig run``: the capture planner in closed loop with the rig (or its pty emulators)."""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

from nlosplan.cli.common import emit, int_type, number_type, sigterm_interrupts
from nlosplan.errors import UserError
from nlosplan.files import check_output_dir, write_json

EXAMPLES = (
    "nlosplan rig run --emulate --planner active --budget 40 --target-rmse 0.05 --store out/loop.db",
    "nlosplan rig run --lidar /dev/ttyACM0 --gantry /dev/ttyUSB0 --planner doptimal --budget 30 --approve "
    "--store runs.db --out out/loop",
    "nlosplan rig run --emulate --planner raster --budget 10 --grid 10 --repeats 1 --store out/loop.db --json",
)

DESCRIPTION = """\
Capture, ingest, update the model and the calibration, suggest the next
batch, until the budget or the target is reached. Candidates: a GRID x GRID
lattice over the gantry limits, screened by the keep-out rules (limits,
object in the LiDAR's direct view); the planner's counts model is simulated
at every candidate first (draft fidelity: about 25 s for 19 x 19 on 2 CPU
cores). Planners: raster (DENALI's snake), random, active (ensemble-spread
mutual information), doptimal (D-optimal calibration design, casadi/IPOPT),
and -motion variants (information per second of gantry travel). Each batch
is route-ordered (nearest neighbour + 2-opt) and run by the rig executor
(every capture stored once; rerunning the same command resumes: stored
captures are fed back and the deterministic planner repeats its choices).
--target-rmse stops when the cross-validated localization RMSE (DENALI's
loc_rmse: x and y errors pooled) of the
ensemble over the captures reaches it. --approve shows each batch (table,
and a PNG of the positions in --out) and waits for 'y' before anything
moves; any other answer ends the run. With --live the batch can also be
approved, edited (drop or add positions on the map) or refused on the live
page (the first answer wins; the page needs the token of the printed URL).
Every answer is logged in --out (approvals.jsonl); a rerun runs the batches
approved before as they were approved (edits included) and asks again from
the first batch that was not.
The planner's JSON checkpoint and the progress are written to --out."""


def _run_id(args) -> str:
    if args.run:
        return args.run
    keys = ("planner", "budget", "batch", "grid", "seed", "object", "size", "zones", "range_mode", "repeats")
    blob = json.dumps({**{k: getattr(args, k) for k in keys},
                       "emulate": True if args.emulate == "both" else (args.emulate or False)}, sort_keys=True)
    return f"plan-{args.planner}-{args.object}-{args.size}-{hashlib.sha256(blob.encode()).hexdigest()[:8]}"


def _approver(args, out: Path, run_id: str):
    from nlosplan.cli.live import ask_approval
    from nlosplan.planner.capture.approval import close_request, given_approval, post_request
    from nlosplan.reports.capture_plan_plot import batch_table, plot_batch

    live = args.live is not None
    asked = [0]

    def approve(batch, planner):
        k = asked[0]
        asked[0] += 1
        png = plot_batch(batch, planner.space.points_mm, planner.space.points_mm[planner.captured],
                         planner.position_mm, out / f"batch_{k:03d}.png",
                         title=f"{planner.config.strategy}: batch of {len(batch)}")
        print(f"proposed batch ({len(planner.observations)} captured so far); plot: {png}\n{batch_table(batch)}",
              file=sys.stderr, flush=True)
        ids = [p["id"] for p in batch]
        budget = planner.config.budget
        left = None if budget is None else int(budget) - len(planner.observations) - sum(
            p["status"] == "pending" for p in planner.proposals.values())
        where = [(p["x_mm"], p["y_mm"]) for p in batch]
        before = given_approval(out, run_id, k, ids, where)
        if before is not None:   # a rerun resumes: the batch was approved then (by whom, when: approvals.jsonl)
            print(f"batch {k} was approved by the {before['answered_by']} at {before['answered_utc']}"
                  + (" with edits" if before["drop"] or before["add"] else "") + ": running it again as approved",
                  file=sys.stderr, flush=True)
            return {"drop": before["drop"], "add": before["add"]} if before["drop"] or before["add"] else True
        while True:   # until an answer the planner can run (an edit from the page is checked first)
            req = post_request(out, run_id=run_id, batch=k, ids=ids, positions=where, budget_left=left)
            print(f"move the gantry to these {len(batch)} positions? [y/N] " + ("(or answer on the live page) "
                                                                              if live else ""),
                  end="", file=sys.stderr, flush=True)
            answer = ask_approval(req, out, live=live)
            if answer.decision == "approve" and answer.edited:
                try:
                    planner.amend(ids, drop=answer.drop, add=answer.add, check_only=True)
                except UserError as exc:
                    close_request(out, req, answer, note=f"not run: {exc}")
                    print(f"\nthe edited batch cannot run: {exc}; asking again", file=sys.stderr, flush=True)
                    continue
                close_request(out, req, answer)
                return {"drop": list(answer.drop), "add": list(answer.add)}
            close_request(out, req, answer)
            return answer.decision == "approve"

    return approve


def _cmd(args) -> int:
    from nlosplan.cli.live import live_page
    from nlosplan.cli.rig.capture import resolve_devices

    devices = resolve_devices(args, seed_is_noise=False)
    args.seed = 0 if args.seed is None else args.seed
    if args.lights == "on":
        raise UserError("rig run plans with a lights-off counts model; --lights on is not supported yet")
    out = check_output_dir(args.out, "--out")   # a read-only or file --out: one line before any work
    run_id = _run_id(args)
    with sigterm_interrupts(), live_page(args, "rig", args.store, planner_dir=out, run_id=run_id,
                                         actions=args.approve):
        out.mkdir(parents=True, exist_ok=True)
        return _loop(args, devices, out, run_id)


def _loop(args, devices: dict, out: Path, run_id: str) -> int:
    from nlosplan.cli.rig.capture import _open, rig_failures
    from nlosplan.hardware.executor import Executor, RunContext
    from nlosplan.hardware.plans import ask_tell_plan
    from nlosplan.hardware.rig import sensor_preset
    from nlosplan.planner.capture import (CapturePlanner, MotionModel, PlannerConfig, build_space, denali_scene_fn,
                                          grid_points, screen_candidates)
    from nlosplan.planner.capture.closed_loop import ClosedLoop
    from nlosplan.data.store import CaptureStore

    # the capture planner's counts model is linear and alike in every zone: the preset without its pile-up and
    # per-zone calibration terms (those serve the realism checks, 'nlosplan bench real')
    from nlosplan.simulators.presets.scene_model import scene_model, scene_options

    model = sensor_preset(args.zones, args.range_mode)
    sensor = model.linear_uniform()
    scene_fn = denali_scene_fn(args.object, args.size, "off", **scene_options(scene_model(model)))
    (x0, x1), (y0, y1) = args.limits
    cand = screen_candidates(grid_points(args.grid, args.grid, (x0, x1), (y0, y1)), limits=args.limits,
                             scene_fn=scene_fn, sensor=sensor)
    if not args.quiet and not args.json:
        print(f"[rig run] simulating the counts model at {len(cand.points_mm)} candidates "
              f"({len(cand.excluded)} excluded) ...", file=sys.stderr, flush=True)
    space = build_space(cand.points_mm, sensor, scene_fn=scene_fn, repeats=args.repeats, excluded=cand.excluded)
    motion = MotionModel(feed_mm_s=args.feed / 60.0, settle_s=args.settle)
    planner = CapturePlanner(space, PlannerConfig(strategy=args.planner, batch_size=args.batch, budget=args.budget,
                                                  seed=args.seed, motion=motion, start_mm=(x0, y0)))

    def report(row):
        if not args.quiet and not args.json:
            cv = row["cv_loc_rmse_m"]
            print(f"[rig run] {row['captures']} captured, {row['failed']} failed, cross-validated RMSE "
                  f"{'n/a (too few)' if cv == float('inf') else f'{1e3 * cv:.1f} mm'}, calibration "
                  f"{[round(v, 4) for v in row['calibration_theta']]}", file=sys.stderr, flush=True)

    loop = ClosedLoop(planner, target_rmse_m=args.target_rmse, checkpoint=out / "planner.json",
                      approve=_approver(args, out, run_id) if args.approve else None, on_batch=report)
    ctx = RunContext(args.object, args.size, lights=False,
                     source="emulated:rig" if "lidar" in devices["emulate"] else "rig",
                     plan=f"planner {args.planner}, budget {args.budget}, batches of {args.batch}",
                     plan_spec={"kind": "planner", "planner": args.planner, "budget": args.budget,
                                "batch": args.batch, "grid": args.grid, "seed": args.seed})
    plan = ask_tell_plan(loop.suggest, loop.ingest, batch=args.batch, repeats=args.repeats, settle_s=args.settle,
                         max_positions=args.budget)
    # what the rig CLI's opener (nlosplan.cli.rig.capture._open) reads besides the options above
    args.no_park, args.sensor_config = False, sensor
    with rig_failures(run_id, args.store) as hold, CaptureStore(args.store) as store, \
            _open(args, devices, store=store, run_id=run_id) as rig:
        ex = hold["executor"] = Executor(rig, store, run_id=run_id, context=ctx)
        summary = ex.run(plan)
    best = planner.best()
    result = {"run_id": run_id, "store": str(args.store), "planner": best, "history": loop.history,
              "executor": summary.to_dict(), "checkpoint": str(out / "planner.json"),
              "excluded": cand.excluded,
              "finished": planner.finished or (f"budget of {args.budget} positions spent"
                                               if best["captures"] >= args.budget else "plan ended")}
    write_json(out / "rig_run.json", result, indent=1, default=float)
    last = loop.history[-1] if loop.history else None
    cv = "n/a" if not last or last["cv_loc_rmse_m"] == float("inf") else f"{1e3 * last['cv_loc_rmse_m']:.1f} mm"
    text = (f"run {run_id}: {best['captures']} positions captured ({summary.captured} captures stored, "
            f"{summary.resumed} found stored), {best['failed']} failed, in {summary.seconds:.1f} s -> {args.store}\n"
            f"stopped: {result['finished']}; cross-validated localization RMSE {cv}\n"
            f"calibration (dx m, dy m, log photon scale, log albedo): "
            f"{[round(v, 5) for v in best['calibration']['theta']]} +- "
            f"{[round(v, 5) for v in best['calibration']['std']]}\nwrote {out / 'rig_run.json'}, "
            f"{out / 'planner.json'}")
    emit(args, result, text)
    return 0


def add_rig(rsub) -> None:
    """Register ``nlosplan rig run``."""
    from nlosplan.cli.rig.capture import _run_name, add_device_options, add_mode_options, add_motion_options
    from nlosplan.planner.capture import STRATEGIES

    p = rsub.add_parser("run", help="closed loop: capture, ingest, update, suggest the next batch (planner)",
                        description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter,
                        epilog="examples:\n" + "\n".join(f"  {e}" for e in EXAMPLES))
    p.add_argument("--planner", default="active", choices=STRATEGIES, help="strategy (default: active)")
    p.add_argument("--budget", type=int_type(1, 10_000), default=40, metavar="N",
                   help="most positions to capture (default: 40)")
    p.add_argument("--target-rmse", type=number_type(float), default=None, metavar="M",
                   help="stop when the cross-validated localization RMSE (m; DENALI's loc_rmse, x and y pooled) "
                        "reaches this, e.g. 0.05")
    p.add_argument("--batch", type=int_type(1, 100), default=5, metavar="N", help="positions per batch (default: 5)")
    p.add_argument("--grid", type=int_type(2, 41), default=19, metavar="N",
                   help="candidate lattice N x N over the limits (default: 19)")
    p.add_argument("--approve", action="store_true", help="show each batch and wait for 'y' before anything moves "
                                                          "(with --live: or for an answer on the page)")
    add_device_options(p, seed_help="planner seed, and the emulated sensor's noise seed (default: 0)")
    p.add_argument("--store", required=True, help="capture store (SQLite; created when missing)")
    p.add_argument("--run", type=_run_name, default=None,
                   help="run id (default: derived from the settings, so a rerun resumes)")
    p.add_argument("--out", default="nlosplan-out/rig-run", metavar="DIR",
                   help="planner checkpoint, batch plots, rig_run.json (default: %(default)s)")
    add_motion_options(p)
    p.add_argument("--object", default="A", help="DENALI object (default: A)")
    p.add_argument("--size", default="8in", choices=["4in", "8in"], help="object size (default: 8in)")
    add_mode_options(p)
    p.add_argument("--lights", default="off", choices=["off", "on"], help="room lights (off only, for now)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    from nlosplan.cli.live import add_live_option

    add_live_option(p, "the run (rig map with the proposed route, histograms, RMSE, calibration; with --approve "
                       "the batch is approved, edited or refused on the page)")
    p.set_defaults(func=_cmd)
