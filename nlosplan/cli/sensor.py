"""``nlosplan sensor``: list, show and measure sensor presets."""

from __future__ import annotations

from nlosplan.cli.common import command_group, emit, sub_parser


def _provenance(name: str) -> str:
    """A few words on where a preset's values come from (``sensor list``)."""
    if name.startswith("denali-"):
        return "DENALI facts + Table-2 fit"
    if name == "tmf8828-3x3-plane-unit":
        return "plane-unit fit"
    if name.startswith("vl53"):
        return "ST docs + assumed"
    if name.endswith("-long"):
        return "driver constant + MEAS"
    return "datasheet + MEAS"


def _cmd_sensor_list(args) -> int:
    from nlosplan.reports.tables import format_table
    from nlosplan.sensor_models import PRESET_NAMES, preset
    from nlosplan.sensor_models.fitted_to import record_summary
    from nlosplan.sensor_models.preset_sources import preset_record
    from nlosplan.simulators.presets.scene_model import CALIBRATED_SCENE_MODELS, DEFAULT_SENSOR

    rows = []
    for name in PRESET_NAMES:
        s = preset(name)
        rows.append(dict(name=name, zones=f"{s.zones_rows}x{s.zones_cols}", bins=s.n_bins,
                         bin_width_ps=s.bin_width_ps, fov_deg=f"{s.fov_x_deg:g}x{s.fov_y_deg:g}",
                         pulse="measured" if s.pulse_shape else f"{s.pulse_fwhm_ps:g} ps",
                         iterations=s.iterations, provenance=_provenance(name),
                         fitted_to=record_summary(preset_record(name)),
                         scene="fitted" if name in CALIBRATED_SCENE_MODELS else "defaults"))
    note = (f"default: {DEFAULT_SENSOR} (design, dataset build, simulate --scene denali, rig emulators); "
            "scene 'fitted': its DENALI scenes take the retro albedo, diffuse base and mount it was fitted with; "
            "fitted_to: the real data its values were fitted to ('none (assumed)': values measured on another unit "
            "or mode; 'sensor show NAME' lists every source)")
    emit(args, {"presets": rows, "default": DEFAULT_SENSOR}, format_table(rows) + "\n" + note)
    return 0


def _cmd_sensor_show(args) -> int:
    from nlosplan.sensor_models import PRESET_NAMES, preset_uncertainty, sensor_base
    from nlosplan.sensor_models.fitted_to import record_dicts, record_lines
    from nlosplan.sensor_models.preset_sources import sensor_record

    s, record, changed, origin = sensor_record(args.name)
    unc = preset_uncertainty(args.name) if args.name in PRESET_NAMES else None
    # --toml/--json: a sensor file with its base preset (later model fields come from it) and the record as far as
    # it still holds for these values, so that a saved copy keeps it
    kept = None if record is None else record_dicts(record)
    if args.toml:
        print(s.to_toml(base=sensor_base(args.name), fitted_to=kept))
    elif args.json:
        print(s.to_json(base=sensor_base(args.name), fitted_to=kept))
    else:
        for k, v in s.to_dict().items():
            if k == "pulse_shape" and v is not None:
                v = f"{len(v)} samples of {s.pulse_shape_step_ps:g} ps, peak at sample {max(range(len(v)), key=v.__getitem__)}"
            print(f"{k:>22} = {v}")
        print("\n".join(record_lines(record, changed, origin)))
        if unc is not None:
            print(f"uncertainty ({len(unc['samples'])} bootstrap refits; 95 % intervals):")
            for k, p in unc["parameters"].items():
                print(f"{k:>22} = {p['value']:.5g} +- {p['std']:.3g} ({p['lo']:.4g} to {p['hi']:.4g})")
    return 0


def _cmd_sensor_fit(args) -> int:
    from nlosplan.calibration.tmf882x_report import fit_report

    report = fit_report(args.path)
    emit(args, report, report["summary"])
    return 0


def add(sub) -> None:
    """The ``sensor`` subcommand and its subcommands."""
    ssub = command_group(sub, "sensor", "list, show and measure sensor presets",
                         "Sensor presets: list them, show one, measure the time base from data.",
                         metavar="SUBCOMMAND")
    s_list = sub_parser(ssub, "list", "sensor list", "list the sensor presets")
    s_list.add_argument("--json", action="store_true", help="machine-readable output")
    s_list.set_defaults(func=_cmd_sensor_list)
    s_show = sub_parser(ssub, "show", "sensor show", "show one preset (or a .toml/.json sensor file)",
                        "Show one preset (or a .toml/.json sensor file): its fields; 'fitted to:', the real data "
                        "its values were fitted to (each source with its file and sha256, the values it gave, what "
                        "the fit held fixed) and those assumed from another unit or mode; a shipped uncertainty. "
                        "--toml/--json print a sensor file that keeps the record ([[fitted_to]] / \"fitted_to\").")
    s_show.add_argument("name", help="preset name or path to a .toml/.json sensor file")
    fmt = s_show.add_mutually_exclusive_group()
    fmt.add_argument("--json", action="store_true", help="print JSON")
    fmt.add_argument("--toml", action="store_true", help="print TOML (save it and pass the file as --sensor)")
    s_show.set_defaults(func=_cmd_sensor_show)
    s_fit = sub_parser(ssub, "fit-timebase", "sensor fit-timebase",
                       "measure bin width, time offset and pulse shape from TMF882x plane-at-distance captures")
    s_fit.add_argument("path", help="JSON list of captures with dist_to_plane, hists, reference_hist")
    s_fit.add_argument("--json", action="store_true", help="machine-readable output")
    s_fit.set_defaults(func=_cmd_sensor_fit)
