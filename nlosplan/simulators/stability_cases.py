"""Stability-catalog cases for the wall scene (zone geometry extremes)."""

from __future__ import annotations

import numpy as np

from nlosplan.errors import UserError
from nlosplan.sensor_models.presets import preset
from nlosplan.simulators.wall import WallScene, simulate_wall, wall_arrivals
from nlosplan.cases import Case


def _finite_nonneg(h) -> bool:
    h = np.asarray(h)
    return bool(np.all(np.isfinite(h)) and np.all(h >= 0))


def _zones(n):
    def run():
        s = preset("tmf8828-3x3-short").replace(zones_rows=n, zones_cols=n)
        h = simulate_wall(WallScene(), s)
        lit = int(np.sum(h.sum(-1) > 0))
        return _finite_nonneg(h) and lit == n * n, f"{n}x{n}: {lit} of {n * n} zones see the wall, max {h.max():.3g}"

    return run


def _fov(deg):
    def run():
        s = preset("tmf8828-3x3-short").replace(fov_x_deg=deg, fov_y_deg=deg)
        t, w = wall_arrivals(WallScene(), s)
        h = simulate_wall(WallScene(), s)
        return _finite_nonneg(h) and _finite_nonneg(w) and w.sum() > 0, f"FoV {deg} deg: weight sum {w.sum():.3e}, max count {h.max():.3g}"

    return run


def _grazing():
    s = preset("tmf8828-3x3-short").replace(fov_x_deg=120.0, fov_y_deg=120.0)
    t, w = wall_arrivals(WallScene(yaw_deg=88.0), s)
    h = simulate_wall(WallScene(yaw_deg=88.0), s)
    return _finite_nonneg(h) and _finite_nonneg(w), f"wall at 88 deg yaw: {int(np.sum(w > 0))} sub-rays hit, all finite"


def _reject_wall():
    try:
        WallScene(distance_m=-1.0)
    except UserError as exc:
        return "distance" in str(exc), f"UserError: {exc}"
    return False, "accepted a negative wall distance"




def _mitsuba_cpu():
    import subprocess
    import sys

    code = (
        "from nlosplan.simulators.mitsuba.env import load_mitsuba, find_libllvm\n"
        "mi, mitr = load_mitsuba('llvm_ad_rgb')\n"
        "import drjit as dr\n"
        "x = dr.llvm.Float([1.0, 2.0]) * 2\n"
        "print(find_libllvm(), mi.__version__, mitr.__version__, float(dr.sum(x)[0] if hasattr(dr.sum(x), '__getitem__') else dr.sum(x)))\n"
    )
    # a separate process: Dr.Jit's LLVM backend must not share this one's state
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    if proc.returncode != 0:
        last = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        return False, last
    lib, mi_v, mitr_v, total = proc.stdout.split()
    return float(total) == 6.0, f"mitsuba {mi_v} llvm_ad_rgb with {lib}, mitransient {mitr_v}; JIT 2*[1,2] sums to {total}"


CASES: list[Case] = [
    Case("zones-1x1", "1x1 zone: finite, non-negative, sees the wall", _zones(1)),
    Case("zones-16x16", "16x16 zones: finite, every zone sees the wall", _zones(16)),
    Case("fov-1deg", "1 deg field of view: finite, positive signal", _fov(1.0)),
    Case("fov-120deg", "120 deg field of view: finite, non-negative", _fov(120.0)),
    Case("grazing-wall", "wall at 88 deg: finite, non-negative (rays missing it get 0)", _grazing),
    Case("reject-wall-distance", "negative wall distance rejected with a clear message", _reject_wall),
    Case("mitsuba-llvm-variant", "Mitsuba CPU variant starts with libLLVM >= 16 found by itself and JIT-runs", _mitsuba_cpu),
]
