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
projectors running during every capture), the lights-on extra
(``ambient_rate_hz``), and the scene parameters of :data:`DENALI_SCENE_FIT`.
Uncertainties: ``data/<preset>.uncertainty.json`` (:func:`.presets.uncertainty`).
"""

from __future__ import annotations

#: Facts of DENALI's capture settings.
DENALI_ITERATIONS = {"3x3": 10_240_000, "8x8": 10_240}
DENALI_FOV_DEG = (41.0, 52.0)

#: The fit's sensor values (3x3 centre zone; the 8x8 preset takes the same per-iteration rates).
DENALI_FIT: dict = {
    "photon_scale": 0.2844,
    "dark_rate_hz": 1.2467e6,
    "ambient_rate_hz": 0.0,
}
#: The fit's scene parameters (``denali_scene`` keywords; wall albedo 0.8).
DENALI_SCENE_FIT: dict = {
    "albedo": 0.362,
    "diffuse_albedo": 0.2,
    "mount": True,
    "mount_albedo": 0.8,
    "mount_in_background": False,
}
#: The fit's protocol nuisances of the Table-2 statistics file (not properties of the unit; see docs/calibration.md).
DENALI_NUISANCES_FIT: dict = {
    "background_offset_on": 0.0234,
    "background_offset_off": -0.007,
    "early_residual_counts": 48.0,
    "early_residual_decay_bins": 3.1,
}
#: Provenance shown by ``nlosplan sensor show`` / ``sensor list``.
DENALI_PROVENANCE = (
    "DENALI unit: iterations ({iterations}), FoV 41x52 deg (SPAD map 6), 128 bins: facts of DENALI's capture code. "
    "Time base and 32-sample pulse: TMF882x MEAS; pulse tail: the plane unit's (chip physics). No per-zone terms "
    "(unknown for this unit). Photon scale, floor in the dark (dark_rate_hz: external IR, not SPAD dark counts) and "
    "lights-on extra (ambient_rate_hz): fitted by 'nlosplan calibrate --stats' on DENALI Table 2 "
    "(calibration/data/denali_table2.toml) with the checkpoint levels. {scores}"
)
#: Scores of the fit ('nlosplan bench real' table2 part; filled from its output).
DENALI_SCORES = "Table 2 scores: see 'nlosplan bench real --parts table2'."
