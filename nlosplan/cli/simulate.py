"""``nlosplan simulate``: one capture of the DENALI rig, a corner or a wall, and a plot of every zone."""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

from nlosplan.cli.common import emit, int_type, note, number_type, seed_type, sub_parser, zones_type
from nlosplan.errors import UserError
from nlosplan.schema import parse_int, parse_number
from nlosplan.files import writing
from nlosplan.sensor_models.config import MAX_BINS
from nlosplan.simulators import BACKENDS

SCENES = ("denali", "corner", "wall")
DEFAULT_OUT = "nlosplan-out/simulate"


NLOS_SCENES = ("denali", "corner")


#: The sensor of the corner and wall scenes when none is given (the datasheet's TMF8828 3x3).
GENERIC_SENSOR = "tmf8828-3x3-short"
#: Sensor flags of ``simulate``: flag, the argparse dest, the SensorConfig field, how the change is named.
_SENSOR_FLAGS = (("--jitter-ps", "jitter_ps", "jitter_fwhm_ps", "jitter {} ps"), ("--bins", "bins", "n_bins", "{} bins"),
                 ("--bin-width-ps", "bin_width_ps", "bin_width_ps", "{} ps bins"))


def _sensor_from_args(args):
    """The ``--sensor`` with the sensor flags applied; a bad combination names the flags as typed."""
    from nlosplan.sensor_models import resolve_sensor

    s = resolve_sensor(args.sensor)
    changes, parts, flags = {}, [], []
    for flag, dest, field, shown in _SENSOR_FLAGS:
        value = getattr(args, dest)
        if value is not None:
            changes[field] = value
            parts.append(shown.format(f"{value:g}"))
            flags.append(f"{flag} {value:g}")
    if args.zones is not None:
        rows, cols = args.zones
        changes.update(zones_rows=rows, zones_cols=cols)
        parts.append(f"{rows}x{cols} zones")
        flags.append(f"--zones {rows}x{cols}")
    if not changes:
        return s
    try:
        return s.replace(name=f"{s.name} ({', '.join(parts)})", **changes)
    except UserError as exc:
        raise UserError(f"{' '.join(flags)} on {s.name}: {exc}") from None


def _warn_zone_mode(args) -> None:
    """A warning line when --zones changes the zone grid of a sensor built for another zone mode."""
    from nlosplan.cli.common import warn
    from nlosplan.sensor_models import PRESET_NAMES, preset, resolve_sensor

    if args.zones is None:
        return
    rows, cols = args.zones
    sensor = resolve_sensor(args.sensor)
    if (rows, cols) == (sensor.zones_rows, sensor.zones_cols):
        return
    text = (f"--zones {rows}x{cols} changes only the zone grid of {sensor.name} ({sensor.zones_rows}x"
            f"{sensor.zones_cols}): it keeps its {sensor.fov_x_deg:g}x{sensor.fov_y_deg:g} deg field of view and "
            f"{sensor.iterations} iterations")
    family = sensor.name.split("-")[0]   # a preset of the same family first (tmf8828-..., denali-...)
    names = sorted(PRESET_NAMES, key=lambda n: n.split("-")[0] != family)
    match = [preset(n) for n in names if (preset(n).zones_rows, preset(n).zones_cols) == (rows, cols)]
    if match:
        m = match[0]
        text += (f"; the {rows}x{cols} preset has {m.fov_x_deg:g}x{m.fov_y_deg:g} deg and {m.iterations} iterations "
                 f"(--sensor {m.name})")
    warn(text)


def _check_scene_options(args) -> None:
    """Reject an option given for a scene it does not apply to (one line, exit 2)."""
    for dest, (flag, scenes) in args.scene_options.items():
        value = getattr(args, dest)
        if value is not None and args.scene not in scenes:
            shown = flag if value is True else f"{flag} {value}"
            allowed = " or ".join(f"--scene {s}" for s in scenes)
            raise UserError(f"{shown} applies only to {allowed}, not to --scene {args.scene}")


def _given(args, **names: str) -> dict:
    """Keyword arguments ``{kwarg: args.<dest>}`` for the options the user gave (the rooms' defaults hold otherwise)."""
    return {kw: getattr(args, dest) for kw, dest in names.items() if getattr(args, dest) is not None}


def _parse_xy(text: str) -> tuple[float, float]:
    """``--object-xy X,Y`` as two floats (metres); the corner scene checks the values."""
    try:
        x, y = (parse_number(v) for v in text.split(","))
    except ValueError:
        raise UserError(f"--object-xy {text!r} must be two numbers X,Y in metres, e.g. 0.45,0.30 "
                        "(write --object-xy=-0.2,0.3 for a negative X)") from None
    return x, y


def _parse_zones(text: str) -> list[tuple[int, int]]:
    """``--only-zones "R,C;R,C"`` as (row, col) pairs; the simulator checks them against the zone grid."""
    try:
        zones = [tuple(parse_int(v) for v in item.split(",")) for item in text.split(";") if item.strip()]
    except ValueError:
        zones = []
    if not zones or any(len(z) != 2 for z in zones):
        raise UserError(f"--only-zones {text!r} must be ROW,COL pairs separated by ';', e.g. '1,1;0,2'")
    return zones


def with_warning_lines(func, *a, **kw):
    """Call ``func``; print each NLOSWarning it issues as one ``nlosplan: warning:`` line on stderr.

    Returns
    -------
    result
        What ``func`` returned.
    list of str
        The warning messages, in order, without repeats.
    """
    from nlosplan.simulators import NLOSWarning

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", NLOSWarning)
        result = func(*a, **kw)
    messages: list[str] = []
    for w in caught:
        if not issubclass(w.category, NLOSWarning):
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)
            continue
        text = " ".join(str(w.message).split())
        if text not in messages:
            messages.append(text)
            print(f"nlosplan: warning: {text}", file=sys.stderr)
    return result, messages


def _denali_options(args, common: dict) -> dict:
    """The DENALI scene's keywords: the sensor's calibrated scene model, then the options given."""
    from nlosplan.simulators.presets.scene_model import scene_model, scene_options

    if args.mount and args.no_mount:
        raise UserError("--mount and --no-mount contradict each other; give one")
    if args.mount_in_signal and args.mount_in_background:
        raise UserError("--mount-in-signal and --mount-in-background contradict each other; give one")
    opts = {**scene_options(scene_model(args.sensor)), **common}
    if args.mount or args.no_mount:
        opts["mount"] = bool(args.mount)
    if args.mount_in_signal or args.mount_in_background:
        if not opts.get("mount"):
            flag = "--mount-in-signal" if args.mount_in_signal else "--mount-in-background"
            raise UserError(f"{flag} needs the mount (--mount, or a sensor whose scene model has it: "
                            f"{args.sensor} has none)")
        opts["mount_in_background"] = bool(args.mount_in_background)
    return opts


def _nlos_scene(args):
    """The DENALI or corner scene from the options given."""
    from nlosplan.simulators import corner_scene, denali_scene

    common = _given(args, reflectance="reflectance", albedo="object_albedo", lobe_fwhm_deg="lobe_deg",
                    diffuse_albedo="diffuse_albedo")
    if args.scene == "denali":
        return denali_scene(**_given(args, obj="object", size="size", position="position"), lights=args.lights,
                            **_denali_options(args, common))
    xy = {} if args.object_xy is None else {"object_xy": _parse_xy(args.object_xy)}
    return corner_scene(**_given(args, wall_distance="wall_distance", object="object", object_size="object_size",
                                 yaw_deg="object_yaw"), **xy, lights_on=args.lights == "on", **common)


#: The files of a DENALI or corner run inside ``--out``, and their arrays.
NLOS_FILES = {"expected": "expected.npy", "background": "background.npy", "signal": "signal.npy",
              "counts": "counts.npy", "background_counts": "background_counts.npy"}
WALL_FILES = {"expected": "expected.npy", "counts": "counts.npy"}
PLOT_FILE = "histograms.png"


def _file_paths(out: Path, legacy: bool, names: dict) -> dict[str, Path]:
    """``{array: path}``: fixed names inside the folder ``out``, or (deprecated ``--out X.npy``) X.npy, X_<name>.npy."""
    if not legacy:
        return {k: out / v for k, v in names.items()}
    return {k: out if k == "expected" else out.with_name(f"{out.stem}_{k}.npy") for k in names}


def _save(arrays: dict, paths: dict[str, Path], seconds: float) -> dict:
    """Write each array (None: skipped) atomically; return ``{name: path}``.

    A failed write (full disk, ...) is one line naming the files written
    before it (complete) and the simulation time lost; nothing partial is left.
    """
    from nlosplan.files import WriteFailed, save_npy

    files: dict[str, str] = {}
    for k, arr in arrays.items():
        if arr is None:
            continue
        try:
            files[k] = str(save_npy(paths[k], arr))
        except WriteFailed as exc:
            done = f"{', '.join(Path(v).name for v in files.values())} written complete, " if files else ""
            raise WriteFailed(f"{exc}; {done}nothing partial left; the {seconds:.1f} s simulation is lost: free some "
                              "space or choose another --out and rerun") from None
    return files


def _nlos_title(args, meta: dict, sensor, fidelity: str) -> str:
    """Two-line plot title: scene, object, position or place, reflectance, lights; sensor, jitter, fidelity."""
    if args.scene == "denali":
        mount = (" + mount (in the signal)" if args.mount_in_signal else " + mount") if args.mount else ""
        what = f"DENALI {meta['object']}_{meta['size']}{mount} at gantry position {meta['position']}"
    else:
        x, y = meta["object_xy"]
        what = (f"corner: {meta['object']} at x = {x:g} m, {y:g} m in front of a relay wall "
                f"{meta['wall_distance']:g} m away")
    return (f"{what}, {meta['reflectance']}, lights {args.lights}\n"
            f"{sensor.name} ({sensor.zones_rows}x{sensor.zones_cols} zones, {sensor.n_bins} bins), "
            f"jitter {sensor.jitter_fwhm_ps:g} ps, fidelity {fidelity}")


def _signal_peaks(signal):
    """Bin of the largest signal per zone, ``None`` where the object adds nothing (nested lists)."""
    import numpy as np

    peaks = signal.argmax(-1).astype(object)
    return np.where(signal.max(-1) > 0, peaks, None).tolist()


def _peak_lines(peaks, zones) -> list[str]:
    """The signal peak bins as a small grid (or one line per requested zone)."""
    show = lambda p: "-" if p is None else str(p)  # noqa: E731
    if zones is not None:
        return [f"  zone ({r},{c}): {show(p)}" for (r, c), p in zip(zones, peaks)]
    width = max(len(show(p)) for row in peaks for p in row)
    return ["  " + " ".join(f"{show(p):>{width}}" for p in row) for row in peaks]


def _nlos_summary(args, scene, sensor, result, zones, fidelity: str, files: dict, warned: list) -> tuple[dict, str]:
    """The JSON summary and the text lines of a DENALI or corner run.

    Returns
    -------
    data : dict
        Scene kind and labels, sensor, shape, totals (expected, background,
        signal), signal peak bin per zone, seconds, files, warnings, and
        ``plan`` (``SimPlan.to_dict()``) with ``--explain``.
    text : str
        A few readable lines; with ``--explain`` the plan table after them.
    """
    import numpy as np

    totals = {k: float(np.sum(getattr(result, k), dtype=np.float64)) for k in ("expected", "background", "signal")}
    peaks = _signal_peaks(result.signal)
    data = {
        "scene": {"kind": args.scene, "name": scene.name, **result.meta},
        "sensor": sensor.name,
        "shape": list(result.expected.shape),
        "zones": None if zones is None else [list(z) for z in zones],
        "fidelity": fidelity,
        "dtype": str(result.expected.dtype),
        "repeats": args.repeats,
        "seed": args.seed,
        "totals": totals,
        "signal_peak_bin_per_zone": peaks,
        "seconds": result.seconds,
        "files": files,
        "warnings": warned,
    }
    if args.explain:
        data["plan"] = result.plan.to_dict()
    share = 100 * totals["signal"] / totals["expected"] if totals["expected"] > 0 else 0.0
    lines = [
        f"simulated {scene.name} with {sensor.name} ({sensor.zones_rows}x{sensor.zones_cols} zones, "
        f"{sensor.n_bins} bins of {sensor.bin_width_ps:g} ps), fidelity {fidelity}, in {result.seconds:.2f} s",
        f"expected counts {totals['expected']:.4g}; object signal (minus the no-object capture) "
        f"{totals['signal']:.4g} ({share:.2g} %)",
        "signal peak bin per zone ('-': no signal):",
        *_peak_lines(peaks, zones),
        *(f"wrote {k}: {v}" for k, v in files.items()),
    ]
    if args.explain:
        lines += ["", result.plan.explain()]
    return data, "\n".join(lines)


def _outputs(args) -> tuple[Path | None, bool, Path | None]:
    """``--out`` (folder, or the deprecated .npy file), whether it is the deprecated form, ``--plot``; checked.

    Everything is checked before any work: the folder (or file) can be
    written, the plot's suffix is a known image type. ``--explain`` alone
    (no ``--out``, no ``--plot``) writes nothing: returns (None, False, None).
    """
    from nlosplan.files import check_output_dir, check_output_file, check_plot_path

    if args.explain and args.out is None and args.plot is None:
        return None, False, None
    out = Path(args.out if args.out is not None else DEFAULT_OUT)
    legacy = out.suffix == ".npy"
    if legacy:
        check_output_file(out, "--out")
    else:
        check_output_dir(out, "--out")
    plot = None
    if args.plot is True:
        plot = (out.parent / (out.stem + ".png")) if legacy else out / PLOT_FILE
    elif args.plot:  # '' (the old way to ask for none) stays none
        plot = Path(args.plot)
    if plot is not None:
        check_plot_path(plot, "--plot")
    return out, legacy, plot


def _warn_before_work(args, out: Path | None, legacy: bool) -> None:
    """Warning lines (a preset's zone mode changed, the deprecated ``--out X.npy``), once every input passed its
    checks: a bad input stays one line."""
    from nlosplan.cli.common import warn

    _warn_zone_mode(args)
    if legacy:
        warn(f"--out {args.out} (a .npy file) is deprecated: give a folder, e.g. --out {out.with_suffix('')}, "
             f"to get {', '.join(NLOS_FILES.values() if args.scene != 'wall' else WALL_FILES.values())} in it")


#: Peak memory of ``simulate``, measured with /usr/bin/time (maximum resident set) on the DENALI scene
#: (docs/reliability.md): about 0.5 GB at 3x3 x 128 bins whatever the fidelity and zones, ~400 bytes more
#: per histogram cell (0.9 GB at 16x16 x 4096), and 56-58 bytes per noisy cell drawn (with and without the
#: object: 1.2 GB at 5,000 repeats of 3x3 x 128, 3.1 GB at 20,000). Rounded up.
_BASE_BYTES = 0.6e9
_BYTES_PER_CELL = 500
_BYTES_PER_DRAWN_CELL = 60


def _check_memory(args, sensor, n_zones: int, out: Path | None) -> None:
    """Refuse, before any work, a run whose estimated peak memory (or output size) exceeds what the machine has."""
    from nlosplan.files import check_free_space
    from nlosplan.resources import check_memory

    cells = n_zones * sensor.n_bins
    drawn = 2 * args.repeats * cells * _BYTES_PER_DRAWN_CELL  # with and without the object
    shown = " ".join(f for f in (f"--repeats {args.repeats}" if args.repeats > 1 else "",
                                  f"--zones {args.zones[0]}x{args.zones[1]}" if args.zones else "",
                                  f"--bins {args.bins}" if args.bins else "") if f) or "this simulation"
    check_memory(_BASE_BYTES + cells * _BYTES_PER_CELL + drawn, shown, "use fewer --repeats, --zones or --bins")
    if out is not None:  # the arrays' size on disk: expected, background, signal; 2 x repeats int64 captures
        floats = 8 if args.scene == "wall" or args.dtype == "float64" else 4
        check_free_space(out, cells * (3 * floats + 2 * args.repeats * 8) + 5 * 128, "--out")


def _simulate_nlos(args, sensor, out, legacy, plot) -> int:
    """``simulate --scene denali|corner``: expected, background, signal, noisy captures, plot, summary."""
    from nlosplan.simulators import explain, simulate

    zones = None if args.only_zones is None else _parse_zones(args.only_zones)
    backend = args.backend or "fast"
    if backend == "mitsuba" and (args.explain or args.dtype):
        raise UserError(f"{'--explain' if args.explain else '--dtype'} applies to the fast backend only, "
                        "not to --backend mitsuba")
    scene = _nlos_scene(args)
    fidelity = args.fidelity or "default"
    if out is None:  # --explain alone: the plan, no simulation, no files
        _warn_before_work(args, None, False)
        plan, warned = with_warning_lines(explain, scene, sensor, fidelity=fidelity, zones=zones)
        data = {"scene": {"kind": args.scene, "name": scene.name}, "sensor": sensor.name, "fidelity": fidelity,
                "plan": plan.to_dict(), "warnings": warned}
        emit(args, data, plan.explain())
        return 0
    _check_memory(args, sensor, len(zones) if zones is not None else sensor.n_zones, out)
    _warn_before_work(args, out, legacy)
    note(args, f"simulating {scene.name} with {sensor.name} ({backend} backend, fidelity {fidelity}) ...")
    result, warned = with_warning_lines(simulate, scene, sensor, rng=args.seed, repeats=args.repeats,
                                         fidelity=fidelity, zones=zones, backend=backend, **_given(args, dtype="dtype"))
    files = _save({k: getattr(result, k) for k in NLOS_FILES}, _file_paths(out, legacy, NLOS_FILES), result.seconds)
    with writing(kept="the arrays are written", cont="free some space or choose another --plot and rerun"):
        if plot is not None:
            from nlosplan.reports import plot_simulation

            labels = None if zones is None else [f"zone ({r},{c})" for r, c in zones]
            plot_simulation(result.expected, result.parts, result.signal, plot, bin_width_ps=sensor.bin_width_ps,
                            start_offset_ps=sensor.start_offset_ps,
                            title=_nlos_title(args, result.meta, sensor, fidelity),
                            samples=None if result.counts is None else result.counts[0], zone_labels=labels)
            files["plot"] = str(plot)
    data, text = _nlos_summary(args, scene, sensor, result, zones, fidelity, files, warned)
    emit(args, data, text)
    return 0


def _simulate_wall(args, sensor, out, legacy, plot) -> int:
    """``simulate --scene wall``: the first-bounce wall capture (expected, noisy captures, plot)."""
    from nlosplan.simulators import WallScene, simulate_wall

    if args.samples is not None and args.samples < 1:
        raise UserError(f"--samples {args.samples} must be >= 1")
    scene = WallScene(**_given(args, distance_m="distance", yaw_deg="yaw", pitch_deg="pitch", albedo="albedo"),
                      lights_on=args.lights == "on")
    _check_memory(args, sensor, sensor.n_zones, out)
    _warn_before_work(args, out, legacy)
    fidelity = _given(args, n_sub="samples")
    t0 = time.perf_counter()
    mean = simulate_wall(scene, sensor, **fidelity)
    counts = simulate_wall(scene, sensor, **fidelity, rng=args.seed, repeats=args.repeats) if args.repeats else None
    seconds = time.perf_counter() - t0
    files = _save({"expected": mean, "counts": counts}, _file_paths(out, legacy, WALL_FILES), seconds)
    with writing(kept="the arrays are written", cont="free some space or choose another --plot and rerun"):
        if plot is not None:
            from nlosplan.reports import plot_zone_histograms

            title = (f"{sensor.name}: wall at {scene.distance_m:g} m (yaw {scene.yaw_deg:g}, pitch {scene.pitch_deg:g} "
                     f"deg), lights {args.lights}, jitter {sensor.jitter_fwhm_ps:g} ps")
            plot_zone_histograms(mean, plot, bin_width_ps=sensor.bin_width_ps, start_offset_ps=sensor.start_offset_ps,
                                 title=title, samples=None if counts is None else counts[0])
            files["plot"] = str(plot)
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
    emit(args, summary, text)
    return 0


def _cmd_simulate(args) -> int:
    """``nlosplan simulate``: check the options and outputs, build the sensor, run the scene."""
    from nlosplan.simulators.presets.scene_model import DEFAULT_SENSOR

    _check_scene_options(args)
    if args.sensor is None:  # DENALI's calibrated unit on its rig; the datasheet's generic unit elsewhere
        args.sensor = DEFAULT_SENSOR if args.scene == "denali" else GENERIC_SENSOR
    out, legacy, plot = _outputs(args)
    sensor = _sensor_from_args(args)
    if args.scene == "wall":
        return _simulate_wall(args, sensor, out, legacy, plot)
    return _simulate_nlos(args, sensor, out, legacy, plot)


SIMULATE_DESCRIPTION = """\
Simulate one capture and write its histograms and a plot of every zone.

scenes:
  denali  the DENALI rig (default): a TMF8828 facing the relay wall, a hidden
          retroreflective object on the gantry (60 meshes, 100 positions)
  corner  a parametric corner: LiDAR, relay wall and a hidden object beside it
  wall    a plain wall in front of the sensor (first bounce only)

outputs (denali, corner), in the folder --out (default: nlosplan-out/simulate):
  expected.npy           expected counts with the object, (rows, cols, bins),
                         or (zones, bins) with --only-zones
  background.npy         the same capture without the object (DENALI's NOOBJECT)
  signal.npy             expected minus background: the object's three-bounce return
  counts.npy             noisy captures, int64, (repeats, ...) when --repeats > 0
  background_counts.npy  noisy captures without the object
  histograms.png         with --plot: a plot of every zone (or --plot PATH)
The wall scene writes expected.npy and counts.npy. --explain alone prints the
plan of terms without simulating or writing anything. (--out X.npy, the old
form, still writes X.npy, X_background.npy, ... beside it, with a warning.)
Options of another scene are rejected."""


def _scene_options(group, scenes: tuple[str, ...], registry: dict):
    """An ``add_argument`` for ``group`` whose options default to None and apply to ``scenes`` only."""

    def add(flag: str, **kw):
        action = group.add_argument(flag, default=None, **kw)
        registry[action.dest] = (flag, scenes)
        return action

    return add


def _add_sensor_and_output(sim) -> None:
    """The options of every scene: the sensor and its overrides, the capture and the outputs."""
    sen = sim.add_argument_group("sensor (all scenes)")
    sen.add_argument("--sensor", default=None,
                     help="preset name or sensor file (default: denali-tmf8828-3x3 for --scene denali, DENALI's unit "
                          "calibrated on the real Table 2, whose scene model sets the object's albedo, diffuse base "
                          f"and mount; {GENERIC_SENSOR} for corner and wall)")
    sen.add_argument("--jitter-ps", type=number_type(float, zero_ok=True), metavar="J",
                     help="override timing jitter FWHM, ps (>= 0)")
    sen.add_argument("--bins", type=int_type(1, MAX_BINS), metavar="N", help=f"override number of bins (1 to {MAX_BINS})")
    sen.add_argument("--bin-width-ps", type=number_type(float), metavar="W", help="override bin width, ps (> 0)")
    sen.add_argument("--zones", type=zones_type, metavar="RxC",
                     help="override the zone grid, e.g. 8x8 (the preset's field of view and iterations stay: a warning "
                          "says so; pick the preset of that zone mode instead)")

    out = sim.add_argument_group("capture and output (all scenes)")
    out.add_argument("--lights", choices=["on", "off"], default="off", help="room lights (default: off)")
    out.add_argument("--repeats", type=int_type(0), default=1, help="noisy captures to draw (default: 1; 0 for none)")
    out.add_argument("--seed", type=seed_type(), default=0, help="random seed of the noisy captures, 0 to 2**32-1 "
                                                                 "(default: 0)")
    out.add_argument("--out", metavar="DIR", help=f"output folder, files with fixed names inside (default: {DEFAULT_OUT})")
    out.add_argument("--plot", nargs="?", const=True, metavar="PATH",
                     help=f"also plot every zone: OUT/{PLOT_FILE}, or PATH (.png, .pdf, .svg, ...)")
    out.add_argument("--json", action="store_true", help="machine-readable summary")


def add(sub) -> None:
    """The ``simulate`` subcommand; scene-specific options are recorded in ``args.scene_options``."""
    sim = sub_parser(sub, "simulate", "simulate", "simulate one capture (DENALI rig, corner or wall) and plot every zone",
               description=SIMULATE_DESCRIPTION)
    only: dict = {}
    sim.add_argument("--scene", choices=SCENES, default="denali", help="scene (default: denali)")

    add = _scene_options(sim.add_argument_group("DENALI rig (--scene denali)"), ("denali",), only)
    add("--size", choices=["4in", "8in"], help="object size (default: 8in)")
    add("--position", type=int, metavar="N", help="gantry position, 0 to 99 (default: 19)")
    add("--mount", action="store_true", help="add the object mount and its plate (Lambertian 0.8); unless the "
                                             "sensor's scene model places them, they stay in the background capture "
                                             "(DENALI's NOOBJECT), so they cancel from the signal")
    add("--no-mount", action="store_true", help="leave the mount out (the default sensor's scene model has it)")
    add("--mount-in-signal", action="store_true", help="a background without the mount (DENALI's NOOBJECTMOUNT), so "
                                                       "the mount's return is in the signal (the default sensor's "
                                                       "scene model)")
    add("--mount-in-background", action="store_true", help="the mount stays in the background capture, so it "
                                                           "cancels from the signal")

    add = _scene_options(sim.add_argument_group("corner (--scene corner)"), ("corner",), only)
    add("--wall-distance", type=float, metavar="M", help="LiDAR to relay wall, metres (default: 0.5)")
    add("--object-xy", metavar="X,Y", help="object centre: lateral X (+ is the LiDAR's right) and distance Y in "
                                            "front of the wall, metres (default: 0.45,0.30; --object-xy=-0.2,0.3 "
                                            "for a negative X)")
    add("--object-size", type=float, metavar="M", help="side of the 'patch' object, metres (default: 0.1)")
    add("--object-yaw", type=float, metavar="DEG", help="object turn about the vertical, degrees (default: 0)")

    add = _scene_options(sim.add_argument_group("hidden object and simulation (--scene denali or corner)"),
                         NLOS_SCENES, only)
    add("--object", help="denali: a DENALI object such as A, 7 or circle (default: A; a wrong name lists all 30); "
                         "corner: patch (default), a DENALI name like A_8in, or an .obj file")
    add("--reflectance", choices=["retroreflective", "lambertian"],
        help="object reflectance (default: retroreflective for denali, lambertian for corner)")
    add("--object-albedo", type=float, metavar="A", help="object albedo, 0..1 (default: the sensor's scene model, "
                                                         "0.367 for denali-tmf8828-*; else 0.5)")
    add("--lobe-deg", type=float, metavar="DEG", help="retroreflective lobe FWHM, degrees (default: 2)")
    add("--diffuse-albedo", type=number_type(float, zero_ok=True, hi=1.0), metavar="A",
        help="Lambertian base of a retroreflective object, 0..1, with object albedo + diffuse albedo <= 1 "
             "(default: the sensor's scene model, 0.2 for denali-tmf8828-*; else 0)")
    add("--backend", choices=list(BACKENDS),
        help="transport: fast (JAX, default) or mitsuba (the Mitsuba 3 + mitransient twin, CPU llvm_ad_rgb or "
             "cuda_ad_rgb; e.g. --backend mitsuba --fidelity low takes ~10 s on 2 cores)")
    add("--fidelity", metavar="LEVEL",
        help="quadrature level: draft, low, default, high or reference (default: default); "
             "for --backend mitsuba the twin's levels (spp 16 to 4096)")
    add("--only-zones", metavar="R,C;R,C",
        help="compute only these zones, e.g. '1,1;0,2' (arrays become (zones, bins))")
    add("--explain", action="store_true", help="print the plan: terms computed and left out, with reasons")
    add("--dtype", choices=["float32", "float64"], help="floating-point precision (default: float32)")

    add = _scene_options(sim.add_argument_group("wall (--scene wall)"), ("wall",), only)
    add("--distance", type=float, metavar="M", help="wall distance, metres (default: 0.49, DENALI's)")
    add("--yaw", type=float, metavar="DEG", help="wall tilt about the vertical axis, degrees (default: 0)")
    add("--pitch", type=float, metavar="DEG", help="wall tilt about the horizontal axis, degrees (default: 0)")
    add("--albedo", type=float, metavar="A", help="wall albedo, 0..1 (default: 0.8)")
    add("--samples", type=int, metavar="N", help="sub-rays per zone axis, the wall's fidelity knob (default: 4)")

    _add_sensor_and_output(sim)
    sim.set_defaults(func=_cmd_simulate, scene_options=only)

