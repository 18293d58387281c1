"""``nlosplan dataset``: build simulated datasets, import and export the DENALI layout, describe a store."""

from __future__ import annotations

import argparse
from contextlib import contextmanager

from nlosplan.cli.common import command_group, emit, int_type, note, number_type, progress_bar, seed_type, sub_parser
from nlosplan.cli.selections import choice_list, fidelity_level, object_list, position_list
from nlosplan.errors import UserError


@contextmanager
def _progress(args, desc: str, unit: str):
    """A ``progress(done, total, text)`` callback showing progress on stderr (tqdm on a terminal, lines otherwise)."""
    with progress_bar(args, None, desc, unit) as bar:
        yield lambda done, total, text: bar.set(done, total, text)


def _store(args, *, create: bool, synchronous: str = "FULL", check: bool = False):
    """The store of ``--store``: opened read-only unless the command writes (``create``); with ``check`` after
    SQLite's quick check (a damaged store is one line before anything is read)."""
    from nlosplan.data.store import CaptureStore

    if create:
        return CaptureStore(args.store, create=True, synchronous=synchronous)
    return CaptureStore(args.store, readonly=True, check=check)


def _check_store_target(path) -> None:
    """``--store`` of a command that writes: a file path in a writable folder, before any work."""
    from pathlib import Path

    from nlosplan.files import check_output_file

    if Path(path).is_dir():
        raise UserError(f"--store {path} is a folder; give a file path such as {Path(path) / 'captures.sqlite'}")
    check_output_file(path, "--store")


#: Bytes per stored capture beyond its histogram (labels, key, metadata, index), measured on SQLite stores.
_ROW_OVERHEAD_BYTES = 600


def _check_build_size(args, sensor) -> None:
    """Refuse a build the disk or the memory cannot hold, before any work (one line)."""
    from nlosplan.files import check_free_space
    from nlosplan.resources import check_memory

    cells = sensor.n_zones * sensor.n_bins
    scenes = len(args.objects) * len(args.sizes) * len(args.positions) * len(args.lights)
    check_free_space(args.store, scenes * args.repeats * (8 * cells + _ROW_OVERHEAD_BYTES), "--store")
    # one batch of Poisson captures: int64 counts and JAX's float32 rates, keys and draws (~4 copies), plus the
    # simulator's own working set
    per_batch = min(args.batch, len(args.positions)) * args.repeats * cells * 8 * 4
    check_memory(per_batch + 1.5e9, f"--repeats {args.repeats} --batch {args.batch}",
                 "use fewer --repeats or a smaller --batch")


# ----------------------------------------------------------------- commands
def _cmd_build(args) -> int:
    from nlosplan.cli.simulate import with_warning_lines
    from nlosplan.data.build import build_dataset
    from nlosplan.files import writing
    from nlosplan.sensor_models import resolve_sensor

    from nlosplan.simulators.presets.scene_model import scene_model, scene_options, session_floor_sd

    sensor = resolve_sensor(args.sensor)
    options = scene_options(scene_model(args.sensor))  # a calibrated sensor's fitted scene (albedo, base, mount)
    sessions = session_floor_sd(scene_model(args.sensor)) if args.session_floor_sd is None else args.session_floor_sd
    _check_store_target(args.store)
    _check_build_size(args, sensor)
    n = len(args.objects) * len(args.sizes) * len(args.positions) * len(args.lights) * args.repeats
    note(args, f"building up to {n} captures into {args.store} ...")
    with writing(cont="free some space and rerun the same command: it resumes where it stopped"), \
            _store(args, create=True, synchronous="FULL" if args.fsync else "NORMAL") as store, \
            _progress(args, "dataset build", "capture") as progress:
        res, warned = with_warning_lines(
            build_dataset, store, scene=args.scene, sensor=sensor, objects=args.objects, sizes=args.sizes,
            positions=args.positions, lights=args.lights, repeats=args.repeats, fidelity=args.fidelity,
            seed=args.seed, reflectance=args.reflectance, scene_options=options, batch=args.batch,
            progress=progress, session_floor_sd=sessions)
    res["warnings"] = warned
    text = (f"stored {res['captures_added']} new captures in {res['store']} ({res['captures_skipped']} of "
            f"{res['captures_total']} were there already; {res['groups_skipped']} of {res['groups']} groups "
            "were complete)\n"
            f"{len(res['objects'])} objects x {len(res['sizes'])} sizes x {len(res['positions'])} positions x "
            f"{len(res['lights'])} lights x {res['repeats']} repeats, {res['sensor']} ({res['zones']}), fidelity "
            f"{args.fidelity}, seed {res['seed']}, session floor spread {100 * res['session_floor_sd']:.2f} %, "
            f"in {res['seconds']:.1f} s ({res['captures_per_second']:.1f} "
            f"captures/s; simulation {res['simulate_seconds']:.1f} s, store {res['store_seconds']:.1f} s)")
    emit(args, res, text)
    return 0


def _skipped_lines(skipped: list[dict], limit: int = 20) -> list[str]:
    lines = [f"  skipped {s['path']}: {s['reason']}" for s in skipped[:limit]]
    if len(skipped) > limit:
        lines.append(f"  ... and {len(skipped) - limit} more (see --json)")
    return lines


def _cmd_import(args) -> int:
    from nlosplan.data.denali_io import import_denali
    from nlosplan.files import writing
    from nlosplan.sensor_models import resolve_sensor

    sensors = [resolve_sensor(s) for s in args.sensor or ()]
    _check_store_target(args.store)
    with writing(cont="free some space and rerun the same command: captures stored already are skipped"), \
            _progress(args, "import DENALI", "file") as progress:
        res = import_denali(args.root, args.store, positions_json=args.positions_json, trust_pickle=args.trust_pickle,
                            sensors=sensors, progress=progress)
    text = "\n".join([f"imported {res['captures_added']} captures from {res['files']} files in {res['folders']} "
                      "folders "
                      f"of {res['root']} into {res['store']} in {res['seconds']:.1f} s "
                      f"({res['captures_skipped']} captures, {res['files_stored_already']} files stored already)",
                      *_skipped_lines(res["skipped"])])
    emit(args, res, text)
    return 0


def _where(args) -> dict:
    names = {"objects": "object", "sizes": "size", "lights": "lights", "zones": "zones", "positions": "position",
             "source": "source", "sensor_hash": "sensor_hash", "seed": "seed"}
    return {col: getattr(args, opt) for opt, col in names.items() if getattr(args, opt, None) is not None}


def _cmd_export(args) -> int:
    from nlosplan.data.denali_io import export_denali
    from nlosplan.files import check_output_dir, writing

    check_output_dir(args.out)
    with _store(args, create=False, check=True) as store, _progress(args, "export DENALI", "file") as progress, \
            writing(kept="the files written before are complete", cont="free some space and rerun the same command "
                                                                      "(equal files are left alone)"):
        res = export_denali(store, args.out, overwrite=args.overwrite, progress=progress, **_where(args))
    emit(args, res, f"wrote {res['files_written']} files ({res['files_unchanged']} unchanged) in {res['folders']} "
                    f"folders, {res['captures']} captures at {res['positions']} positions, to {res['root']}")
    return 0


def _cmd_info(args) -> int:
    with _store(args, create=False) as store:
        by = ("source", "zones", "lights", "size") + (("object",) if args.by_object else ())
        table, sensors = store.summary(by=by), store.sensors()
        total = store.count()
    data = {"store": str(args.store), "captures": total, "sensors": sensors.to_dict("records"),
            "groups": table.to_dict("records")}
    text = "\n".join([f"{args.store}: {total} captures", "", "sensors:",
                      sensors.to_string(index=False) if len(sensors) else "  (none)", "",
                      "captures:", table.to_string(index=False) if len(table) else "  (none)"])
    emit(args, data, text)
    return 0


# ----------------------------------------------------------------- parser
BUILD_DESCRIPTION = """\
Simulate DENALI captures into a capture store (SQLite): every object x size x
position x lights scene through the fast simulator, 'repeats' Poisson captures
each, with noise seeds derived from the seed and the scene. Captures stored
already are skipped, so an interrupted build resumes where it stopped and
gives the same counts as an uninterrupted one.

The default sensor is DENALI's unit as calibrated on the real Table 2
(denali-tmf8828-3x3: its real floor of ~10^3 counts per bin, 10.24 M
iterations); its scenes take the scene parameters it was fitted with (retro
albedo 0.37, a diffuse base of 0.2, the mount in the signal). Any other
sensor (e.g. --sensor tmf8828-3x3-short, the datasheet's generic unit) keeps
the scene's own defaults (albedo 0.5, no diffuse base, no mount)."""

EXPORT_DESCRIPTION = """\
Write the captures of a store that match the filters in the public DENALI
layout: ROOT/<obj>_<4inch|8inch>_<3x3|8x8>_<lighton|lightoff>_NLOSdata/
spad_histogram/NNN.npy, shape (repeats, H, W, 128), and ROOT/tag1_positions.json
with the (x, y) of every exported position. Averaged captures (repeat < 0)
are never exported. An existing tag1_positions.json is merged. A file (or
a position) that holds other data stops the export with an error unless
--overwrite is given; equal files are left alone, so an export can be rerun."""

IMPORT_DESCRIPTION = """\
Import the real DENALI captures: spad_histogram/NNN.npy of every
<object>_<4inch|8inch>_<3x3|8x8>_<lighton|lightoff>_NLOSdata folder, one
capture per repeat, (x, y) of capture number NNN from tag1_positions.json.
The captures are stored with DENALI's unit as their sensor
(denali-tmf8828-3x3 / -8x8) unless --sensor names another.
Unknown folders and files are listed and skipped; captures stored already are
skipped (rerun to resume). Files that need pickle are refused unless
--trust-pickle is given."""


def _filters(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("filters (all given must hold)")
    g.add_argument("--objects", type=object_list, metavar="A,S,...", help="objects, class groups or 'all'")
    g.add_argument("--sizes", type=choice_list(("4in", "8in")), metavar="4in,8in", help="object sizes")
    g.add_argument("--lights", type=choice_list(("on", "off")), metavar="on,off", help="room lights")
    g.add_argument("--zones", type=lambda t: [z.strip() for z in t.split(",") if z.strip()], metavar="3x3,8x8",
                   help="zone modes")
    g.add_argument("--positions", type=position_list, metavar="0-99", help="gantry positions, e.g. 0-99 or 0,5,9")
    g.add_argument("--source", metavar="NAME", help="capture source, e.g. real:denali or sim:fast")
    g.add_argument("--sensor-hash", metavar="HASH", help="one stored sensor (see 'nlosplan dataset info')")
    g.add_argument("--seed", type=seed_type(), help="build seed of simulated captures")


def add(sub) -> None:
    """The ``dataset`` subcommand with ``build``, ``import-denali``, ``export-denali`` and ``info``."""
    dsub = command_group(sub, "dataset", "build, import, export and describe capture stores",
                         "Capture stores (SQLite): simulated DENALI datasets, the real DENALI folder layout, and what a "
                         "store holds.",
                         metavar="SUBCOMMAND")

    b = sub_parser(dsub, "build", "dataset build",
                   "simulate DENALI captures (Poisson counts) into a store; rerun to resume",
                   description=BUILD_DESCRIPTION)
    b.add_argument("--store", required=True, help="capture store file (created when missing)")
    b.add_argument("--scene", choices=["denali"], default="denali", help="scene preset (default: denali)")
    b.add_argument("--sensor", default="denali-tmf8828-3x3",
                   help="preset name or sensor file (default: %(default)s, DENALI's unit calibrated on Table 2, "
                        "whose scenes take the fitted retro albedo, diffuse base and mount in the signal)")
    b.add_argument("--objects", type=object_list, default=object_list("all"), metavar="A,S,...",
                   help="objects, class groups (numbers, letters, shapes) or 'all' (default: all 30)")
    b.add_argument("--sizes", type=choice_list(("4in", "8in")), default=["4in", "8in"], metavar="4in,8in",
                   help="object sizes (default: 4in,8in)")
    b.add_argument("--positions", type=position_list, default=position_list("0-99"), metavar="0-99",
                   help="gantry positions, e.g. 0-99, 0,5,9 or 0-9,50-59 (default: 0-99)")
    b.add_argument("--lights", type=choice_list(("on", "off")), default=["off"], metavar="on,off",
                   help="room lights (default: off)")
    b.add_argument("--repeats", type=int_type(1), default=3, help="Poisson captures per scene (default: 3)")
    b.add_argument("--fidelity", type=fidelity_level, default="default",
                   help="simulator level: draft, low, default, high, reference (default: default)")
    b.add_argument("--reflectance", choices=["retroreflective", "lambertian"], default="retroreflective",
                   help="object reflectance (default: retroreflective)")
    b.add_argument("--seed", type=seed_type(), default=0, help="build seed, 0 to 2**32-1 (default: 0)")
    b.add_argument("--batch", type=int_type(1), default=100, help="positions per run (default: 100): the positions are cut into runs of N and "
                   "every object and lighting of a run is simulated together, up to 1,200 scenes per call; keep it "
                   "when resuming (it fixes the float32 rounding of the means)")
    b.add_argument("--session-floor-sd", type=number_type(float, zero_ok=True, hi=0.5), default=None, metavar="F",
                   help="spread of the floor between capture sessions, a fraction of the floor: every capture of one "
                        "object, size and lighting (one DENALI folder, recorded in one sitting) has its floor moved "
                        "by the same draw (default: the sensor's scene model: 0.0173 for DENALI's unit, from its "
                        "Table-2 fit's background offsets; 0 for other sensors; 0 turns it off)")
    b.add_argument("--fsync", action="store_true",
                   help="fsync every commit (survives power cuts; a build resumes identically anyway)")
    b.add_argument("--json", action="store_true", help="machine-readable summary")
    b.set_defaults(func=_cmd_build)

    i = sub_parser(dsub, "import-denali", "dataset import-denali",
                   "import a DENALI data folder (<obj>_<4inch|8inch>_<3x3|8x8>_<lighton|lightoff>_NLOSdata) "
                   "into a store",
                   description=IMPORT_DESCRIPTION)
    i.add_argument("root", help="folder holding the *_NLOSdata folders")
    i.add_argument("--store", required=True, help="capture store file (created when missing)")
    i.add_argument("--positions-json", metavar="FILE", help="tag1_positions.json (default: the packaged DENALI one)")
    i.add_argument("--sensor", action="append", metavar="SPEC",
                   help="sensor for the folders of its zone mode (preset or file; repeatable; default: "
                        "DENALI's unit, denali-tmf8828-3x3 and denali-tmf8828-8x8)")
    i.add_argument("--trust-pickle", action="store_true",
                   help="allow capture files that need pickle (they may run code when loaded): trusted data only")
    i.add_argument("--json", action="store_true", help="machine-readable summary")
    i.set_defaults(func=_cmd_import)

    e = sub_parser(dsub, "export-denali", "dataset export-denali",
                   "write captures of a store in the DENALI folder layout, with tag1_positions.json",
                   description=EXPORT_DESCRIPTION)
    e.add_argument("--store", required=True, help="capture store file")
    e.add_argument("--out", required=True, metavar="ROOT", help="output folder (created)")
    e.add_argument("--overwrite", action="store_true", help="replace files that hold other data")
    e.add_argument("--json", action="store_true", help="machine-readable summary")
    _filters(e)
    e.set_defaults(func=_cmd_export)

    n = sub_parser(dsub, "info", "dataset info", "what a capture store holds: sensors and captures by group")
    n.add_argument("--store", required=True, help="capture store file")
    n.add_argument("--by-object", action="store_true", help="one row per object too")
    n.add_argument("--json", action="store_true", help="machine-readable output")
    n.set_defaults(func=_cmd_info)
