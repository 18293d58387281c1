"""The ``fitted_to`` records of the presets, and the record of any sensor spec (:mod:`.fitted_to`).

:func:`preset_record` writes down, from the facts of :mod:`.presets` and
:mod:`.presets_denali`, which real data each preset's values were fitted to
(DENALI's Table 2 and checkpoint levels, the TMF882x plane captures) and which
were measured on another unit or mode and assumed; :func:`sensor_record` gives
the record of a preset name, a sensor file or a :class:`~.config.SensorConfig`
as far as it still holds for its values.
"""

from __future__ import annotations

from nlosplan.sensor_models.fitted_to import RealSource, current_record, parse_record

#: sha256 of the shipped DENALI Table 2 statistics file (nlosplan/calibration/data/denali_table2.toml), unchanged
#: since it was written and since the fit that made the denali-tmf8828-* presets (tests check it still is).
TABLE2_SHA256 = "58483e17a4214b19d6f47f9b321655650f65bd87f5d0a6bd7bcd8e1e65bf43fc"
TABLE2_REF = "nlosplan/calibration/data/denali_table2.toml (package data, shipped name 'denali-table2')"
#: sha256 of ../shared/data/tmf882x_distance/distance_data_even.json (the plane captures).
PLANE_SHA256 = "70d2b90a298cc94907caefef49ec466a5d9646873af9c71930e97a45403ee099"
PLANE_REF = ("../shared/data/tmf882x_distance/distance_data_even.json (80 captures: the even half of "
             "cpsiff/SPAD-ICCP-Summer-School part_2_active_SPADs/data/distance_data.json @ 6d924f9)")


def sensor_record(spec):
    """``(sensor, record, changed, origin)`` for a preset name, a sensor file or a :class:`SensorConfig`.

    ``record`` is the part of the recorded sources that still holds (:func:`current_record`), None when nothing
    was recorded (a sensor file without ``base`` or ``fitted_to``, a sensor that is no preset); ``changed`` the
    parameters the sensor no longer takes from them; ``origin`` says where the record came from, in words.

    Raises
    ------
    UserError
        An unknown preset, or a sensor file that does not load (one line).
    """
    from nlosplan.schema import load_table
    from nlosplan.sensor_models.config import SensorConfig
    from nlosplan.sensor_models.presets import PRESET_NAMES, resolve_sensor, sensor_base

    sensor = resolve_sensor(spec)
    if isinstance(spec, SensorConfig) or not str(spec).endswith((".toml", ".json")):
        base = sensor_base(spec)
        if base is None:
            return sensor, None, [], "no record (a sensor that is no preset)"
        return sensor, *current_record(sensor, preset_record(base)), f"the preset {base}'s record"
    data = load_table(spec, "sensor file")
    if "fitted_to" in data:
        record = parse_record(data["fitted_to"], f"sensor file {spec}: fitted_to")
        return sensor, *current_record(sensor, record), "the file's own record"
    base = data.get("base")
    if isinstance(base, str) and base in PRESET_NAMES:
        return sensor, *current_record(sensor, preset_record(base)), f"its base preset {base}'s record"
    return sensor, None, [], "no record (the file has neither 'base' nor 'fitted_to')"


def _params(sensor, names) -> dict:
    return {k: getattr(sensor, k) for k in names}


_TIMEBASE = ("bin_width_ps", "start_offset_ps", "pulse_shape", "pulse_shape_step_ps", "pulse_shape_t0_ps")
_LEVELS = ("photon_scale", "ambient_rate_hz", "dark_rate_hz")
_UNIT = ("bin_width_ps", "start_offset_ps", "pulse_shape", "pulse_shape_step_ps", "pulse_shape_t0_ps",
         "pulse_tail_fraction", "pulse_tail_decay_ps", "photon_scale", "iterations", "time_walk_ps",
         "zone_time_offsets_ps", "zone_time_scales", "zone_gains", "zone_overlap_m")


def _meas(sensor, use: str, timebase, levels, assumed_why: str = "") -> list[RealSource]:
    """The MEAS entries (:data:`~.presets.MEASURED`): the time base and pulse, and the signal level and floors."""
    why = f"; {assumed_why}" if assumed_why else ""
    out = []
    if timebase:
        out.append(RealSource(
            source="TMF882x plane captures: time base and pulse", ref=PLANE_REF, sha256=PLANE_SHA256, use=use,
            what=("centre zone of the 69 captures at 6-40 cm of a TMF882x unit in 3x3 short-range mode facing a "
                  "plane: half-maximum leading edge against distance (bin width, zero-distance bin) and a 32-sample "
                  f"pulse by non-negative least squares{why}"),
            by="nlosplan sensor fit-timebase (calibration/tmf882x_fit.py)", parameters=_params(sensor, timebase)))
    if levels:
        out.append(RealSource(
            source="TMF882x plane captures: signal level and floors", ref=PLANE_REF, sha256=PLANE_SHA256, use=use,
            what=("centre zone of the plane captures: signal / wall-model weight at 0.25-0.40 m, taking 550k "
                  "iterations (photon scale); the floor, ~160 counts/bin at 0.4 m in room light (ambient) and ~1.1 "
                  f"with the plane at 5 mm (dark){why}"),
            by="measured by nlosplan (sensor_models/presets.py MEASURED)", parameters=_params(sensor, levels)))
    return out


def _denali(sensor, zones: str) -> list[RealSource]:
    from nlosplan.sensor_models import presets_denali as d

    use = "fitted" if zones == "3x3" else "assumed"
    carried = "" if zones == "3x3" else ("; the 3x3 centre-zone fit's per-iteration values, not fitted on the 8x8 "
                                         "rows (at 10,240 iterations they are floor noise, < 1 count per bin)")
    fitted = _params(sensor, ("photon_scale", "dark_rate_hz"))
    by = "nlosplan calibrate --stats denali-table2 --bootstrap 40 --variants"
    return [
        RealSource(source="DENALI Table 2", ref=TABLE2_REF, sha256=TABLE2_SHA256, use=use, by=by,
                   what=("DENALI (CVPR 2026) Table 2: total, centroid, spread and skew (mean +- SEM) of the 3x3 "
                         "centre zone's three-bounce signal, lights on/off x 4-inch/8-inch objects, and their 4 "
                         "ratios, with DENALI's processing (repeat means minus the 8-inch NOOBJECT background, bins "
                         f"< 70 zeroed, clip at 0){carried}"),
                   parameters=fitted, scene={"albedo": d.DENALI_SCENE_FIT["albedo"], **d.denali_nuisances(zones),
                                             "session_floor_sd": d.DENALI_SESSION_FLOOR_SD},
                   held={"ambient_rate_hz": sensor.ambient_rate_hz,
                         **{k: d.DENALI_SCENE_FIT[k] for k in ("diffuse_albedo", "mount_albedo",
                                                               "mount_in_background")}}),
        RealSource(source="DENALI checkpoint levels", ref=TABLE2_REF + ", its [[levels]]", sha256=TABLE2_SHA256,
                   use=use, by=by,
                   what=("centre-zone level of DENALI's real 3x3 captures read from the first layers of DENALI's "
                         "public checkpoints (../shared/data/denali/hist_stats.md): mean count per bin 5020, mean "
                         f"log1p count 7.43; fitted jointly with Table 2 (one objective){carried}"),
                   parameters=fitted),
        *_meas(sensor, "assumed", _TIMEBASE, (), "measured on another TMF882x unit, assumed for DENALI's (the "
                                                 "chip's time base and pulse)"),
        RealSource(source="TMF882x plane captures: pulse tail", ref=PLANE_REF, sha256=PLANE_SHA256, use="assumed",
                   what=("the exponential pulse tail of the all-zone plane fit (tmf8828-3x3-plane-unit), assumed "
                         "for DENALI's unit as chip physics"),
                   by="nlosplan calibrate (all-zone plane model, calibration/plane_fit.py)",
                   parameters=_params(sensor, ("pulse_tail_fraction", "pulse_tail_decay_ps"))),
    ]


def _plane_unit(sensor) -> list[RealSource]:
    return [
        RealSource(source="TMF882x plane captures: all-zone fit", ref=PLANE_REF, sha256=PLANE_SHA256, use="fitted",
                   what=("all 9 zones of the 69 captures at 6-40 cm: per-zone time offsets, time scales, gains and "
                         "near-field overlap, first-photon pile-up at the captures' iterations, time walk, pulse "
                         "with an exponential tail"),
                   by="nlosplan calibrate (all-zone plane model, calibration/plane_fit.py)",
                   parameters=_params(sensor, _UNIT)),
        RealSource(source="TMF882x plane captures: floors", ref=PLANE_REF, sha256=PLANE_SHA256, use="fitted",
                   what=("the floors of the same captures (~160 counts/bin at 0.4 m in room light, ~1.1 with the "
                         "plane at 5 mm), as rates at this unit's iterations"),
                   by="measured by nlosplan (sensor_models/presets.py MEASURED)",
                   parameters=_params(sensor, ("ambient_rate_hz", "dark_rate_hz"))),
    ]


def preset_record(name: str) -> tuple[RealSource, ...]:
    """The real sources a preset's values come from (facts of :mod:`.presets` and :mod:`.presets_denali`).

    Raises
    ------
    UserError
        For an unknown preset name.
    """
    from nlosplan.sensor_models.presets import preset

    s = preset(name)
    if name == "tmf8828-3x3-short":
        out = _meas(s, "fitted", _TIMEBASE, _LEVELS)
    elif name in ("tmf8828-4x4-short", "tmf8828-8x8-short"):
        out = _meas(s, "assumed", _TIMEBASE, _LEVELS, f"measured in 3x3 mode, assumed for the {name[8:11]} map")
    elif name == "tmf8828-3x3-long":
        out = _meas(s, "assumed", _TIMEBASE[1:], _LEVELS, "measured at short range (92.8 ps bins); the "
                    "zero-distance bin, pulse, photon scale and floors assumed for long range (no long-range data; "
                    "its 260 ps bins are the driver's constant)")
    elif name == "vl53l8ch-8x8":
        out = _meas(s, "assumed", (), _LEVELS, "measured on a TMF882x, assumed for the VL53L8CH (no VL53L8CH data)")
    elif name == "tmf8828-3x3-plane-unit":
        out = _plane_unit(s)
    elif name.startswith("denali-tmf8828-"):
        out = _denali(s, name[-3:])
    else:  # a preset added later without its record: say so rather than claim datasheet values
        raise UserError(f"the preset {name} has no fitted_to record; add one in sensor_models/preset_sources.py")
    return tuple(out)
