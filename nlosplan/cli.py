"""The ``nlosplan`` command: argument parsing and calls into the rooms.

User errors (:class:`nlosplan.errors.UserError`, bad arguments) print one
line on stderr and exit with code 2; no traceback.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from nlosplan import __version__
from nlosplan.errors import UserError

EXIT_USAGE = 2


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose errors are one line and exit 2."""

    def error(self, message: str):  # noqa: D401 - argparse API
        raise UserError(f"{self.prog}: {message} (see '{self.prog} --help')")


def _emit(args, data, text: str) -> None:
    if getattr(args, "json", False):
        print(json.dumps(data, indent=2, default=float))
    else:
        print(text)


# ----------------------------------------------------------------- sensor
def _cmd_sensor_list(args) -> int:
    from nlosplan.reports.tables import format_table
    from nlosplan.sensor_models import PRESET_NAMES, preset

    rows = []
    for name in PRESET_NAMES:
        s = preset(name)
        rows.append(dict(name=name, zones=f"{s.zones_rows}x{s.zones_cols}", bins=s.n_bins,
                         bin_width_ps=s.bin_width_ps, fov_deg=f"{s.fov_x_deg:g}x{s.fov_y_deg:g}",
                         pulse="measured" if s.pulse_shape else f"{s.pulse_fwhm_ps:g} ps",
                         iterations=s.iterations))
    _emit(args, {"presets": rows}, format_table(rows))
    return 0


def _cmd_sensor_show(args) -> int:
    from nlosplan.sensor_models import resolve_sensor

    s = resolve_sensor(args.name)
    if args.toml:
        print(s.to_toml())
    elif args.json:
        print(s.to_json())
    else:
        for k, v in s.to_dict().items():
            if k == "pulse_shape" and v is not None:
                v = f"{len(v)} samples of {s.pulse_shape_step_ps:g} ps, peak at sample {max(range(len(v)), key=v.__getitem__)}"
            print(f"{k:>22} = {v}")
    return 0


def _cmd_sensor_fit(args) -> int:
    from nlosplan.sensor_models.tmf882x_report import fit_report

    report = fit_report(args.path)
    _emit(args, report, report["summary"])
    return 0


# ----------------------------------------------------------------- simulate
def _sensor_from_args(args):
    from nlosplan.sensor_models import resolve_sensor

    s = resolve_sensor(args.sensor)
    changes = {}
    if args.jitter_ps is not None:
        changes["jitter_fwhm_ps"] = args.jitter_ps
    if args.bins is not None:
        changes["n_bins"] = args.bins
    if args.bin_width_ps is not None:
        changes["bin_width_ps"] = args.bin_width_ps
    if args.zones is not None:
        try:
            r, c = (int(x) for x in args.zones.lower().split("x"))
        except ValueError:
            raise UserError(f"--zones {args.zones!r} must look like 3x3 or 8x8") from None
        changes.update(zones_rows=r, zones_cols=c)
    return s.replace(**changes) if changes else s


def _cmd_simulate(args) -> int:
    import numpy as np

    from nlosplan.reports import plot_zone_histograms
    from nlosplan.simulators import WallScene, simulate_wall

    sensor = _sensor_from_args(args)
    if args.samples < 1:
        raise UserError(f"--samples {args.samples} must be >= 1")
    if args.repeats < 0:
        raise UserError(f"--repeats {args.repeats} must be >= 0")
    scene = WallScene(distance_m=args.distance, yaw_deg=args.yaw, pitch_deg=args.pitch,
                      albedo=args.albedo, lights_on=args.lights == "on")
    t0 = time.perf_counter()
    mean = simulate_wall(scene, sensor, n_sub=args.samples)
    counts = simulate_wall(scene, sensor, n_sub=args.samples, rng=args.seed, repeats=args.repeats) if args.repeats else None
    seconds = time.perf_counter() - t0
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    np.save(out, mean)
    files = {"expected": str(out)}
    if counts is not None:
        cpath = out.with_name(out.stem + "_counts.npy")
        np.save(cpath, counts)
        files["counts"] = str(cpath)
    if args.plot:
        title = (f"{sensor.name}: wall at {scene.distance_m:g} m (yaw {scene.yaw_deg:g}, pitch {scene.pitch_deg:g} deg), "
                 f"lights {args.lights}, jitter {sensor.jitter_fwhm_ps:g} ps")
        plot_zone_histograms(mean, args.plot, bin_width_ps=sensor.bin_width_ps, start_offset_ps=sensor.start_offset_ps,
                             title=title, samples=None if counts is None else counts[0])
        files["plot"] = str(args.plot)
    peak_bins = mean.argmax(-1)
    summary = {
        "scene": {"kind": "wall", **scene.__dict__},
        "sensor": sensor.name,
        "shape": list(mean.shape),
        "total_expected_counts": float(mean.sum()),
        "peak_bin_per_zone": peak_bins.tolist(),
        "seconds": seconds,
        "files": files,
    }
    text = (f"simulated {sensor.name} ({sensor.zones_rows}x{sensor.zones_cols} zones, {sensor.n_bins} bins) "
            f"facing a wall at {scene.distance_m:g} m in {seconds:.2f} s\n"
            f"peak bin per zone:\n{peak_bins}\n" + "\n".join(f"wrote {k}: {v}" for k, v in files.items()))
    _emit(args, summary, text)
    return 0


# ----------------------------------------------------------------- check
def _cmd_check(args) -> int:
    from nlosplan.reports.tables import format_table
    from nlosplan.stability import all_cases, run_cases

    cases = all_cases()
    progress = None
    if not args.json and sys.stderr.isatty():
        from tqdm import tqdm

        bar = tqdm(total=len(cases), desc="stability cases", unit="case", file=sys.stderr, leave=False)
        progress = lambda _r: bar.update(1)  # noqa: E731
    results = run_cases(cases, progress)
    ok = all(r.passed for r in results)
    data = {"passed": ok, "cases": [{"name": r.name, "passed": r.passed, "requirement": r.requirement,
                                     "detail": r.detail, "seconds": round(r.seconds, 3)} for r in results]}
    rows = [{"case": r.name, "must hold": r.requirement, "measured": r.detail,
             "result": "pass" if r.passed else "FAIL"} for r in results]
    n_pass = sum(r.passed for r in results)
    text = format_table(rows) + f"\n\n{n_pass} of {len(results)} cases passed"
    _emit(args, data, text)
    return 0 if ok else 1


# ----------------------------------------------------------------- bench
def _cmd_bench_histogram(args) -> int:
    from nlosplan.reports.tables import format_table
    from nlosplan.sensor_models.bench import bench_histogram

    res = bench_histogram(batch=args.batch, min_seconds=args.seconds, arrivals_per_zone=args.arrivals)
    cols = ["zones", "dtype", "mode", "frames_per_second", "zone_histograms_per_second", "compile_seconds", "speedup_vs_numpy"]
    _emit(args, res, format_table(res["rows"], cols) + f"\n({res['config']['terms']}; "
          f"{res['config']['arrivals_per_zone']} arrivals per zone; devices {res['config']['jax_devices']})")
    return 0


# ----------------------------------------------------------------- parser
EXAMPLES = {
    "sensor list": "nlosplan sensor list",
    "sensor show": "nlosplan sensor show tmf8828-3x3-short --json",
    "sensor fit-timebase": "nlosplan sensor fit-timebase ../shared/data/tmf882x_distance/distance_data_even.json",
    "simulate": "nlosplan simulate --sensor tmf8828-8x8-short --distance 0.6 --yaw 20 --jitter-ps 100 --out out/h.npy --plot out/h.png",
    "check": "nlosplan check --json",
    "bench histogram": "nlosplan bench histogram --json",
}


def _sub(subparsers, name: str, key: str, help_text: str) -> argparse.ArgumentParser:
    return subparsers.add_parser(name, help=help_text, description=help_text, epilog=f"example:\n  {EXAMPLES[key]}",
                                 formatter_class=argparse.RawDescriptionHelpFormatter)


def build_parser() -> argparse.ArgumentParser:
    """The full ``nlosplan`` argument parser."""
    p = _Parser(prog="nlosplan", formatter_class=argparse.RawDescriptionHelpFormatter,
                description="Sensor design and experiment planning for non-line-of-sight imaging "
                            "with low-cost flash dToF LiDARs (TMF8828 class).",
                epilog="examples:\n" + "\n".join(f"  {v}" for v in EXAMPLES.values()))
    p.add_argument("--version", action="version", version=f"nlosplan {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)

    sensor = sub.add_parser("sensor", help="list, show and measure sensor presets",
                            description="Sensor presets: list them, show one, measure the time base from data.")
    ssub = sensor.add_subparsers(dest="sensor_command", metavar="SUBCOMMAND", parser_class=_Parser)
    s_list = _sub(ssub, "list", "sensor list", "list the sensor presets")
    s_list.add_argument("--json", action="store_true", help="machine-readable output")
    s_list.set_defaults(func=_cmd_sensor_list)
    s_show = _sub(ssub, "show", "sensor show", "show one preset (or a .toml/.json sensor file)")
    s_show.add_argument("name", help="preset name or path to a .toml/.json sensor file")
    fmt = s_show.add_mutually_exclusive_group()
    fmt.add_argument("--json", action="store_true", help="print JSON")
    fmt.add_argument("--toml", action="store_true", help="print TOML (save it and pass the file as --sensor)")
    s_show.set_defaults(func=_cmd_sensor_show)
    s_fit = _sub(ssub, "fit-timebase", "sensor fit-timebase",
                 "measure bin width, time offset and pulse shape from TMF882x plane-at-distance captures")
    s_fit.add_argument("path", help="JSON list of captures with dist_to_plane, hists, reference_hist")
    s_fit.add_argument("--json", action="store_true", help="machine-readable output")
    s_fit.set_defaults(func=_cmd_sensor_fit)

    sim = _sub(sub, "simulate", "simulate", "simulate the histograms of a sensor facing a wall (first bounce)")
    sim.add_argument("--scene", choices=["wall"], default="wall", help="scene (default: wall)")
    sim.add_argument("--sensor", default="tmf8828-3x3-short", help="preset name or sensor file (default: %(default)s)")
    sim.add_argument("--distance", type=float, default=0.49, help="wall distance in metres (default: %(default)s, DENALI's)")
    sim.add_argument("--yaw", type=float, default=0.0, help="wall tilt about the vertical axis, degrees")
    sim.add_argument("--pitch", type=float, default=0.0, help="wall tilt about the horizontal axis, degrees")
    sim.add_argument("--albedo", type=float, default=0.8, help="wall albedo, 0..1 (default: %(default)s)")
    sim.add_argument("--lights", choices=["on", "off"], default="off", help="ambient light (default: off)")
    sim.add_argument("--jitter-ps", type=float, help="override timing jitter FWHM, ps")
    sim.add_argument("--bins", type=int, help="override number of bins")
    sim.add_argument("--bin-width-ps", type=float, help="override bin width, ps")
    sim.add_argument("--zones", help="override zone grid, e.g. 8x8")
    sim.add_argument("--samples", type=int, default=4, help="sub-rays per zone axis, the fidelity knob (default: 4)")
    sim.add_argument("--repeats", type=int, default=1, help="noisy captures to draw (default: 1; 0 for none)")
    sim.add_argument("--seed", type=int, default=0, help="random seed for the noisy captures")
    sim.add_argument("--out", default="nlosplan-out/histogram.npy", help="expected histogram .npy, shape (rows, cols, bins)")
    sim.add_argument("--plot", default="nlosplan-out/histogram.png", help="PNG plot of every zone ('' for none)")
    sim.add_argument("--json", action="store_true", help="machine-readable summary")
    sim.set_defaults(func=_cmd_simulate)

    chk = _sub(sub, "check", "check", "run the stability catalog (stiff and extreme cases); exit 0 only if all pass")
    chk.add_argument("--json", action="store_true", help='print {"cases": [{"name", "passed", "detail"}...]}')
    chk.set_defaults(func=_cmd_check)

    bench = sub.add_parser("bench", help="benchmarks that print figures", description="Benchmarks that print figures.")
    bsub = bench.add_subparsers(dest="bench_command", metavar="BENCHMARK", parser_class=_Parser)
    bh = _sub(bsub, "histogram", "bench histogram",
              "histograms per second: 3x3x128 and 8x8x128, jitter + ambient + Poisson, single and vmap-batched")
    bh.add_argument("--batch", type=int, default=256, help="frames per batched call (default: %(default)s)")
    bh.add_argument("--seconds", type=float, default=1.0, help="minimum timed seconds per figure")
    bh.add_argument("--arrivals", type=int, default=16, help="arrival impulses per zone (default: %(default)s)")
    bh.add_argument("--json", action="store_true", help="machine-readable output")
    bh.set_defaults(func=_cmd_bench_histogram)
    return p


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        func = getattr(args, "func", None)
        if func is None:
            parser.print_help(sys.stderr)
            return EXIT_USAGE
        return int(func(args) or 0)
    except UserError as exc:
        print(f"nlosplan: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("nlosplan: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
