"""Stability-catalog cases for histogram formation (see DESIGN.md).

Each function returns ``(passed, measured)``; :data:`CASES` lists them.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import erf

from nlosplan._jax import jax, jnp
from nlosplan.constants import MAX_COUNT_24BIT
from nlosplan.errors import UserError
from nlosplan.sensor_models.binning import bin_boxes, bin_impulses
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.sensor_models.counts import coates_correction, pileup_expected
from nlosplan.sensor_models.noise import sample_poisson
from nlosplan.sensor_models.pipeline import apply_jitter, expected_histogram, sample_histogram
from nlosplan.sensor_models.presets import preset
from nlosplan.cases import Case

_EDGES = np.arange(129, dtype=np.float64) * 100.0  # 128 bins of 100 ps


def _ok(a) -> bool:
    a = np.asarray(a)
    return bool(np.all(np.isfinite(a)) and np.all(a >= 0))


def _jitter_zero():
    h = np.asarray(bin_impulses(np.array([5050.0]), np.array([3.0]), _EDGES, 0.0))
    g = jax.grad(lambda s: bin_impulses(jnp.array([5050.0]), jnp.array([3.0]), _EDGES, s)[50])(0.0)
    return bool(h[50] == 3.0 and h.sum() == 3.0 and np.isfinite(g)), f"bin50={h[50]}, sum={h.sum()}, d/dsigma={float(g)}"


def _jitter_huge():
    sigma = 1e6  # ~80x the 12.8 ns window
    h = np.asarray(bin_impulses(np.array([6400.0]), np.array([1.0]), _EDGES, sigma))
    want = erf(6400.0 / (sigma * math.sqrt(2)))
    rel = abs(h.sum() - want) / want
    return _ok(h) and rel < 1e-9, f"sum={h.sum():.6e}, analytic={want:.6e}, rel err={rel:.1e}"


def _pulse_narrow():
    h = np.asarray(bin_impulses(np.array([5030.0]), np.array([1.0]), _EDGES, 10.0 / 2.3548))
    n = int(np.sum(h > 1e-12))
    return _ok(h) and abs(h.sum() - 1) < 1e-12 and n <= 2, f"sum={h.sum():.15f}, bins above 1e-12: {n}"


def _bins(n):
    def run():
        s = SensorConfig(n_bins=n, bin_width_ps=12800.0 / n, iterations=1, saturation=False)
        h = np.asarray(expected_histogram(s, np.array([3333.0]), np.array([1.0])))
        return _ok(h) and abs(h.sum() - 1) < 1e-9, f"{n} bins, sum={h.sum():.12f}"

    return run


def _photons_zero():
    s = preset("tmf8828-3x3-short").replace(photon_scale=0.0, ambient_rate_hz=0.0, dark_rate_hz=0.0)
    c = np.asarray(sample_histogram(0, s, np.full((3, 3, 1), 3000.0), np.ones((3, 3, 1))))
    return bool(np.all(c == 0)), f"max count={c.max()}"


def _photons_huge():
    s = preset("tmf8828-3x3-short").replace(iterations=10**12)
    c = np.asarray(sample_histogram(0, s, np.full((3, 3, 1), 3000.0), np.ones((3, 3, 1))))
    return _ok(c) and c.max() == MAX_COUNT_24BIT and c.dtype == np.int64, f"max={c.max()}, dtype={c.dtype}"


def _saturation():
    s = SensorConfig(iterations=10**9, photon_scale=1.0)
    mean = np.asarray(expected_histogram(s, np.array([5000.0]), np.array([1.0])))
    c = np.asarray(sample_histogram(1, s, np.array([5000.0]), np.array([1.0])))
    return bool(mean.max() == MAX_COUNT_24BIT and c.max() == MAX_COUNT_24BIT), f"mean max={mean.max():.0f}, sample max={c.max()}"


def _pileup_extreme():
    lam = np.zeros(128)
    lam[10], lam[40] = 1e3, 5.0
    e = np.asarray(pileup_expected(lam, 1e6))
    return _ok(e) and abs(e[10] - 1e6) < 1e-6 and e[40] == 0.0, f"bin10={e[10]:.6f}, bin40={e[40]:.3e}, sum={e.sum():.6f}"


def _coates_roundtrip():
    lam = np.linspace(0.0, 0.05, 128)
    back = np.asarray(coates_correction(pileup_expected(lam, 1e6), 1e6))
    err = np.max(np.abs(back - lam))
    return err < 1e-9, f"max |lam - coates(pileup(lam))| = {err:.1e} (total rate {lam.sum():.1f}/iteration)"


def _dynamic_range():
    t, w = np.array([3000.0, 3350.0]), np.array([1e7, 10.0])
    h64 = np.asarray(bin_impulses(t, w, _EDGES, 60.0))
    h32 = np.asarray(bin_impulses(t.astype(np.float32), w.astype(np.float32), _EDGES.astype(np.float32), np.float32(60.0)))
    sl = slice(33, 35)
    rel = np.max(np.abs(h32[sl] - h64[sl]) / h64[sl])
    return _ok(h32) and rel < 1e-3, f"10-count return bins f32 vs f64 rel diff {rel:.1e}; far bins f32 max {h32[60:].max():.1e}"


def _poisson_huge():
    c = np.asarray(sample_poisson(jax.random.key(0), jnp.full((1000,), 1e12)))
    z = (c.mean() - 1e12) / (1e6 / math.sqrt(1000))
    return bool(c.dtype == np.int64 and c.min() > 0 and abs(z) < 6), f"mean={c.mean():.6e}, z={z:.2f}"


def _poisson_small():
    c = np.asarray(sample_poisson(jax.random.key(1), jnp.full((100_000,), 0.5)))
    z = (c.mean() - 0.5) / math.sqrt(0.5 / 1e5)
    return abs(z) < 5 and np.all(c >= 0), f"mean={c.mean():.4f}, var={c.var():.4f}, z={z:.2f}"


def _gradients():
    s = preset("tmf8828-3x3-short")

    def total(t, sig):
        return bin_impulses(t, jnp.ones_like(t), _EDGES, sig).sum() + bin_boxes(t, 50.0, jnp.ones_like(t), _EDGES, sig)[30]

    t = jnp.array([3000.0, 3100.0])
    g_t0 = jax.grad(total, argnums=(0, 1))(t, 0.0)
    g_t1 = jax.grad(total, argnums=(0, 1))(t, s.impulse_sigma_ps)
    vals = np.concatenate([np.ravel(np.asarray(x)) for x in (*g_t0, *g_t1)])
    return bool(np.all(np.isfinite(vals))), f"{vals.size} gradient entries finite (sigma 0 and {s.impulse_sigma_ps:.0f} ps)"


def _jitter_on_histograms():
    h = np.zeros(128)
    h[60:68] = 100.0
    j = np.asarray(apply_jitter(h, 600.0, 91.0))
    return _ok(j) and abs(j.sum() - h.sum()) < 1e-9 * h.sum(), f"sum before {h.sum():.1f}, after {j.sum():.10f}"


def _measured_pulse():
    s = SensorConfig(pulse_shape=(0.1, 1.0, 0.4, 0.1, 0.05), pulse_shape_step_ps=91.0, pulse_shape_t0_ps=-91.0,
                     iterations=1, saturation=False, jitter_fwhm_ps=50.0)
    h = np.asarray(expected_histogram(s, np.array([4000.0, 4020.0]), np.array([1.0, 2.0])))
    return _ok(h) and abs(h.sum() - 3.0) < 1e-9, f"sum={h.sum():.12f} (expected 3)"


def _zone_terms_extreme():
    """Offsets beyond the window, gain 0, overlap 1 km, walk of 1000 ps/decade on 1e-30 light, tail 0.99."""
    s = SensorConfig(zones_rows=1, zones_cols=4, pulse_shape=(0.2, 0.6, 0.2), pulse_shape_step_ps=100.0, iterations=10,
                     saturation=False, zone_time_offsets_ps=(-1e6, 1e6, 0.0, 0.0), zone_gains=(1.0, 1.0, 0.0, 1.0),
                     zone_overlap_m=(0.0, 0.0, 0.0, 1e3), time_walk_ps=1000.0, pulse_tail_fraction=0.99,
                     pulse_tail_decay_ps=1e5, pileup=True, dead_time_ps=1.0)
    t, w = np.full((4, 2), 5000.0), np.array([[1.0, 1.0], [1.0, 1.0], [1.0, 1.0], [1e-30, 1.0]])
    h = np.asarray(expected_histogram(s, t, w))

    def total(g):
        return expected_histogram(s.replace(zone_gains=(1.0, 1.0, 1.0, 1.0)), t, w * g)[3].sum()

    grad = float(jax.grad(total)(1.0))
    return _ok(h) and h[:2].sum() == 0 and h[2].sum() == 0 and math.isfinite(grad), \
        f"sums per zone {np.round(h.sum(-1), 6).tolist()}, d/dgain {grad:.3g}"


def _deadtime_regimes():
    """DENALI-like floor (1e3 counts/bin at 550k): finite; dead time 0.01 bin to 1e6 bins; 1e6 SPADs."""
    lam = np.full(128, 1e3 / 550_000)
    lam[60] += 0.5
    from nlosplan.sensor_models.counts import deadtime_expected

    outs = [np.asarray(deadtime_expected(lam, 550_000.0, m, d)) for m, d in ((1, 0.01), (1, 1e6), (8, 5.0),
                                                                              (10**6, None))]
    shadow = outs[1][61:].mean() / outs[1][:59].mean()
    return all(_ok(o) for o in outs) and shadow < 1.0, (f"floor {outs[1][:10].mean():.0f} counts/bin, after a 0.5 "
                                                        f"photon return x{shadow:.3f}; 1e6 SPADs sum {outs[3].sum():.0f}")


def _rejects(make, must_contain):
    def run():
        try:
            make()
        except UserError as exc:
            msg = str(exc)
            return (must_contain in msg and "\n" not in msg), f"UserError: {msg}"
        return False, "accepted invalid input"

    return run


CASES: list[Case] = [
    Case("jitter-zero", "zero jitter: exact step, all mass in one bin, finite d/dsigma", _jitter_zero),
    Case("jitter-huge", "jitter 80x the window: finite, sum equals the analytic in-window fraction (1e-9)", _jitter_huge),
    Case("pulse-narrower-than-bin", "10 ps pulse, 100 ps bins: mass conserved, <= 2 bins", _pulse_narrow),
    Case("bins-1", "one bin: finite, conserves mass", _bins(1)),
    Case("bins-4096", "4096 bins: finite, conserves mass", _bins(4096)),
    Case("photons-0", "photon budget 0: all counts exactly 0", _photons_zero),
    Case("photons-1e12", "1e12 iterations: int64 counts, no overflow, clipped at 2^24-1", _photons_huge),
    Case("saturation-24bit", "mean and sampled counts clip at 16,777,215", _saturation),
    Case("pileup-p-to-1", "detection probability -> 1: finite, all iterations in the first bin", _pileup_extreme),
    Case("coates-roundtrip", "Coates correction inverts pile-up (1e-9)", _coates_roundtrip),
    Case("dynamic-range-f32", "1e7 peak beside a 10-count return: float32 within 1e-3 of float64", _dynamic_range),
    Case("poisson-1e12", "Poisson mean 1e12: int64, positive, unbiased (|z| < 6)", _poisson_huge),
    Case("poisson-0.5", "Poisson mean 0.5: exact sampler unbiased (|z| < 5)", _poisson_small),
    Case("gradients-finite", "gradients finite at sigma 0 and sigma > 0, impulses and boxes", _gradients),
    Case("jitter-on-histograms", "600 ps jitter on a central histogram conserves counts (1e-9)", _jitter_on_histograms),
    Case("measured-pulse", "sampled pulse shape + jitter conserves mass (1e-9)", _measured_pulse),
    Case("zone-terms-extreme", "offsets beyond the window, gain 0, overlap 1 km, walk on 1e-30 light, tail 0.99, "
         "1 ps dead time: finite, >= 0, lost zones exactly 0, finite gradient", _zone_terms_extreme),
    Case("dead-time-regimes", "dead time 0.01 bin .. 1e6 bins, 1e6 SPADs, a 1e3 floor at 550k iterations: finite, "
         "the floor shadowed after a return", _deadtime_regimes),
    Case("reject-zone-list-length", "a per-zone list of the wrong length rejected, one line naming it",
         _rejects(lambda: SensorConfig(zone_gains=(1.0, 2.0)), "zone_gains has 2 values")),
    Case("reject-negative-dead-time", "a dead time <= 0 rejected", _rejects(lambda: SensorConfig(dead_time_ps=0.0),
                                                                             "dead_time_ps")),
    Case("reject-negative-jitter", "negative jitter rejected, one line naming it",
         _rejects(lambda: SensorConfig(jitter_fwhm_ps=-1.0), "jitter_fwhm_ps")),
    Case("reject-zero-bins", "zero bins rejected, one line naming it", _rejects(lambda: SensorConfig(n_bins=0), "n_bins")),
    Case("reject-17-zones", "17x17 zones rejected", _rejects(lambda: SensorConfig(zones_rows=17, zones_cols=17), "zones_rows")),
    Case("reject-nan-bin-width", "NaN bin width rejected", _rejects(lambda: SensorConfig(bin_width_ps=float("nan")), "bin_width_ps")),
    Case("reject-bad-pulse-shape", "negative pulse-shape samples rejected",
         _rejects(lambda: SensorConfig(pulse_shape=(1.0, -0.5)), "pulse_shape")),
    Case("reject-unknown-preset", "unknown preset rejected, known ones listed", _rejects(lambda: preset("tmf9999"), "tmf8828-3x3-short")),
]
