"""The DENALI unit's presets (``denali-tmf8828-3x3``, ``denali-tmf8828-8x8``) and their provenance.

Facts (DENALI's code, NikhilBehari/denali @ 9e10832, MIT: ``tmf8828_app.cpp``,
the driver's start sequences, ``spads/tmf8828.py``): the 3x3 captures run the
TMF882x firmware with 10,000 kilo-iterations = 10,240,000 laser iterations and
SPAD map 6 ("wide 3x3", 41 x 52 deg); the 8x8 captures 10 kilo-iterations =
10,240. 128 bins, 24-bit. Time base and pulse: the TMF882x MEAS values of
:mod:`.presets` (bin width, offset, 32-sample pulse) with the plane unit's
exponential pulse tail: the chip's, not per-unit skews (the plane unit's
per-zone terms are NOT facts of DENALI's unit and are left out).

Fitted (``nlosplan calibrate --stats`` on the shipped DENALI Table 2 file,
:data:`DENALI_FIT`): photon scale, the floor of the unit in the dark
(``dark_rate_hz``: not SPAD dark counts but external IR, likely the RealSense
projectors running during every capture) and the scene parameters of
:data:`DENALI_SCENE_FIT`; the lights-on extra (``ambient_rate_hz``) is held
at 0 (not in the fit's default ``--fit``). The record of these sources is
:func:`.preset_sources.preset_record`.
Uncertainties: ``data/denali-tmf8828-3x3.uncertainty.json`` (:func:`.presets.preset_uncertainty`; the sensor
fields only, as its contract says; the scene parameters' and nuisances' intervals are
:data:`DENALI_SCENE_INTERVALS`). The 8x8 preset ships none: its values are the 3x3
fit's per-iteration rates, not fitted on the 8x8 rows (they are floor noise).
"""

from __future__ import annotations

#: Facts of DENALI's capture settings.
DENALI_ITERATIONS = {"3x3": 10_240_000, "8x8": 10_240}
DENALI_FOV_DEG = (41.0, 52.0)

#: The fit's sensor values (3x3 centre zone; the 8x8 preset takes the same per-iteration rates).
DENALI_FIT: dict = {
    "photon_scale": 0.28395,
    "dark_rate_hz": 1.24506e6,
    "ambient_rate_hz": 0.0,
}
#: The fit's scene parameters (``denali_scene`` keywords; wall albedo 0.8).
DENALI_SCENE_FIT: dict = {
    "albedo": 0.3667,
    "diffuse_albedo": 0.2,
    "mount": True,
    "mount_albedo": 0.8,
    "mount_in_background": False,
}
#: The fit's protocol nuisances of the Table-2 statistics file (not properties of the unit; see docs/calibration.md).
DENALI_NUISANCES_FIT: dict = {
    "background_offset_on": 0.02349,
    "background_offset_off": -0.00695,
    "early_residual_counts": 48.76,
    "early_residual_decay_bins": 2.716,
}


#: Spread (standard deviation, fraction of the floor) of the floor from one capture session to the next: the rms of
#: the Table-2 fit's two background offsets (:data:`DENALI_NUISANCES_FIT`: DENALI's no-object background captures,
#: recorded in their own sessions, sit 2.3 % above the object captures' floor with the lights on and 0.7 % below with
#: them off), sqrt((0.02349**2 + 0.00695**2) / 2) = 1.73 %. DENALI records every folder (one object, size and
#: lighting: 100 positions x 3 repeats) in one session, so each folder's floor is its own draw
#: (``dataset build --session-floor-sd``, :func:`nlosplan.data.build.session_shift`). Two offsets make a rough
#: estimate; docs/tasks.md gives what the term does to a learner under DENALI's split.
DENALI_SESSION_FLOOR_SD: float = round(((DENALI_NUISANCES_FIT["background_offset_on"] ** 2
                                         + DENALI_NUISANCES_FIT["background_offset_off"] ** 2) / 2) ** 0.5, 5)


def denali_nuisances(zones: str) -> dict:
    """The Table-2 fit's protocol nuisances for a zone mode: the 3x3 fit's, with the early residual (counts per
    capture) scaled by the iterations (8x8: 10,240 / 10,240,000), the background offsets (fractions of the floor)
    kept."""
    out = dict(DENALI_NUISANCES_FIT)
    out["early_residual_counts"] *= DENALI_ITERATIONS[zones] / DENALI_ITERATIONS["3x3"]
    return out


#: Intervals of the fitted scene parameters and nuisances, (value, std, lo, hi): the spread of 40 bootstrap refits
#: within the SEMs and 80 model-variant refits (:mod:`nlosplan.calibration.stats_variants`: repeat-mean or single
#: captures x 5 readings of the checkpoint levels x diffuse base 0-0.3 x mount in/out of the background).
#: ``diffuse_albedo`` is not fitted: each variant fixes it (0, 0.1, 0.2, 0.3), so its interval is that range.
DENALI_SCENE_INTERVALS: dict = {
    "albedo": (0.3667, 0.0462, 0.3532, 0.4909),
    "diffuse_albedo": (0.2, 0.113, 0.0, 0.3),
    "background_offset_on": (0.02349, 0.0129, 0.02275, 0.05143),
    "background_offset_off": (-0.00695, 0.0065, -0.00809, 0.00732),
    "early_residual_counts": (48.76, 16.5, 44.67, 93.44),
    "early_residual_decay_bins": (2.716, 0.701, 1.0, 3.367),
}
#: Provenance shown by ``nlosplan sensor show`` / ``sensor list``.
DENALI_PROVENANCE = (
    "DENALI unit: iterations ({iterations}), FoV 41x52 deg (SPAD map 6): facts of DENALI's capture code; zones, "
    "128 bins, 24-bit: DS. Time base and 32-sample pulse: TMF882x MEAS; pulse tail: the plane unit's (chip physics). No per-zone terms "
    "(unknown for this unit). Photon scale and floor in the dark (dark_rate_hz: external IR, not SPAD dark counts): "
    "fitted by 'nlosplan calibrate --stats' on DENALI Table 2 (calibration/data/denali_table2.toml) with the "
    "checkpoint levels; the lights-on extra (ambient_rate_hz) held at 0 (not fitted). Sources: 'fitted to' in "
    "'nlosplan sensor show'. {scores}"
)
#: Scores of the fit ('nlosplan calibrate --stats denali-table2 --bootstrap 40 --variants', 300 scenes per size,
#: 3 noise seeds).
DENALI_SCORES = (
    "Fit: objective 35.6, converged; Table 2 (3x3): 13 of 16 row statistics and 4 of 4 ratios within target; "
    "missed: centroids of on-4in (+1.2 bins), on-8in (-1.8) and off-8in (-1.4). Sensor-field intervals: "
    "data/denali-tmf8828-3x3.uncertainty.json (40 bootstrap refits within the SEMs + 80 model-variant refits: "
    "repeat-mean or single captures, checkpoint levels read 3 % low or high, diffuse base 0-0.3, mount in or out "
    "of the background): photon scale +-2.2 % (95 % -4.3 to +4.8 %), floor +-1.9 % (-4.3 to +3.6 %). "
    "See docs/calibration.md."
)
