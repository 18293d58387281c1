"""One-call time-base report for ``nlosplan sensor fit-timebase``.

Runs :mod:`nlosplan.calibration.tmf882x_fit` on a file of plane-at-distance
captures: the time base and pulse shape on every usable capture, and a
seeded fit/held-out split for honest errors. Returns plain data.
"""

from __future__ import annotations

import dataclasses

from nlosplan.calibration.tmf882x_fit import fit_pulse_shape, fit_timebase, holdout_report, load_distance_captures


def fit_report(path, *, zone: int = 4, min_distance_m: float = 0.06, seed: int = 0) -> dict:
    """Fit and validate the time base of a TMF882x from plane captures.

    Parameters
    ----------
    path : str or Path
        JSON list with ``dist_to_plane``, ``hists`` (9 x 128), ``reference_hist``.
    zone : int
        Zone index used (4 = centre of 3x3).
    min_distance_m : float
        Nearer captures are left out (near field, crosstalk overlap).
    seed : int
        Seed of the fit/held-out split.

    Returns
    -------
    dict
        ``timebase``, ``pulse``, ``holdout`` (dataclasses as dicts),
        ``preset_values`` (fields for a SensorConfig) and ``summary`` (text).
    """
    caps = load_distance_captures(path)
    tb = fit_timebase(caps, zone=zone, min_distance_m=min_distance_m)
    pulse = fit_pulse_shape(caps, tb, zone=zone, min_distance_m=min_distance_m)
    hold = holdout_report(caps, seed=seed, zone=zone, min_distance_m=min_distance_m)
    preset_values = {
        "bin_width_ps": tb.bin_width_ps,
        "start_offset_ps": tb.start_offset_ps,
        "pulse_shape": list(pulse.samples),
        "pulse_shape_step_ps": pulse.step_ps,
        "pulse_shape_t0_ps": pulse.t0_ps,
        "pulse_fwhm_ps": 0.0,
    }
    summary = (
        f"time base from {tb.n_used} captures ({caps.distance_m.size} in file), zone {zone}, d >= {min_distance_m} m\n"
        f"  bin width      {tb.bin_width_ps:.2f} +- {tb.bin_width_se_ps:.2f} ps (line-fit s.e.), {tb.bins_per_m:.2f} bins/m\n"
        f"  zero distance  bin {tb.zero_bin:.3f}  -> start_offset_ps {tb.start_offset_ps:.1f}\n"
        f"  residual RMS   {tb.residual_rms_bins:.3f} bin\n"
        f"pulse shape: {len(pulse.samples)} samples of {pulse.step_ps:.2f} ps, t0 {pulse.t0_ps:.1f} ps, "
        f"core FWHM {pulse.core_fwhm_ps:.0f} ps, residual RMS {pulse.residual_rms:.4f} (unit-area histograms)\n"
        f"held out ({hold.n_holdout} captures; fit on {hold.n_fit}, seed {seed}):\n"
        f"  peak-bin error mean {hold.peak_bin_error_mean_abs:.3f}, max {hold.peak_bin_error_max_abs} bin\n"
        f"  normalised L1 of the shape mean {hold.l1_mean:.3f}, max {hold.l1_max:.3f}"
    )
    return {
        "timebase": {k: v for k, v in dataclasses.asdict(tb).items() if k != "indices"},
        "pulse": dataclasses.asdict(pulse),
        "holdout": dataclasses.asdict(hold),
        "preset_values": preset_values,
        "summary": summary,
    }
