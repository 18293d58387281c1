"""The mean real capture behind DENALI's networks, recovered from their BatchNorm statistics.

DENALI's real-trained 1D CNNs (:mod:`nlosplan.tasks.denali_checkpoints`) keep, in every BatchNorm layer, the
running mean and variance of that layer's input over DENALI's real training captures: per network 128 + 128 + 64
channel means and as many variances, each a known function of the captures (the layers before it are fixed).
They are real measurements of DENALI's captures through known filters, and this module reads one thing from
them: the **mean capture** (9 zones x 128 bins).

Model: a real capture is an unknown mean capture ``m`` plus the simulated captures' own variation around their
mean (``x_real = m + (x_sim - mean(x_sim))``), so only the mean is fitted. ``m`` is positive (fitted as
``log m``), smooth in time (a penalty on the second difference of ``log m``, weight ``smooth``), and chosen by
L-BFGS to bring every BatchNorm input of the given networks to the real running statistics: the sum over
networks, layers and channels of ``z**2`` (``z`` the channel mean's distance in running standard deviations)
and ``log(var / running_var)**2``, each layer's mean over its channels.

What it identifies (tested on statistics set from captures with a known mean, ``tests/test_denali_inversion.py``):
the zones' **relative timing** (to about 2 bins: BatchNorm pools over time, so the absolute time is not
identified) and which zones are brighter. Not identified: the absolute time, the direct return's width (a
smoothness penalty favours broad peaks; the test's widths come back 6-10 bins for 3.5-7 bins, out of order) and
how a zone's level splits into peak and floor. If the networks stay at chance on ``m + (x_sim - mean)`` once
the statistics are met, the simulated captures differ from real ones in how they *vary* (what carries the
task), not in their mean.
"""

from __future__ import annotations

import copy
import time

import numpy as np
import torch
from torch import nn

from nlosplan.errors import UserError

__all__ = ["invert_mean_capture", "zone_summary"]


def zone_summary(mean: np.ndarray) -> list[dict]:
    """Robust features of a mean capture, per zone.

    Parameters
    ----------
    mean : ndarray, shape (zones, bins)
        Counts per bin.

    Returns
    -------
    list of dict
        Per zone: ``zone``, ``peak_bin`` (argmax), ``peak`` (counts), ``fwhm_bins`` (width at half the peak's
        height above the floor after it, linearly interpolated), ``floor_before`` (median of the bins more than
        10 before the peak, counts per bin; None if none), ``floor_after`` (median of the bins from 30 after the
        peak to the end, else of the last 10 bins), ``mean`` (counts per bin over the window).
    """
    m = np.asarray(mean, dtype=np.float64)
    if m.ndim != 2 or m.shape[1] < 16:
        raise UserError(f"a mean capture is (zones, bins) with at least 16 bins, got {m.shape}")
    out = []
    for z, h in enumerate(m):
        p = int(np.argmax(h))
        after = h[p + 30:] if p + 30 < len(h) - 4 else h[-10:]
        floor_after = float(np.median(after))
        before = h[:max(p - 10, 0)]
        half = floor_after + (h[p] - floor_after) / 2.0
        lo = p
        while lo > 0 and h[lo - 1] > half:
            lo -= 1
        hi = p
        while hi < len(h) - 1 and h[hi + 1] > half:
            hi += 1
        left = lo - 1 + (half - h[lo - 1]) / (h[lo] - h[lo - 1]) if lo > 0 else float(lo)
        right = hi + (h[hi] - half) / (h[hi] - h[hi + 1]) if hi < len(h) - 1 else float(hi)
        out.append({"zone": z, "peak_bin": p, "peak": float(h[p]), "fwhm_bins": float(right - left),
                    "floor_before": float(np.median(before)) if len(before) else None,
                    "floor_after": floor_after, "mean": float(h.mean())})
    return out


def _cnns(checkpoints) -> list:
    nets = [(c.name, c.net) for c in checkpoints if any(isinstance(m, nn.BatchNorm1d) for m in c.net.modules())]
    if not nets:
        raise UserError("the inversion needs DENALI's 1D CNNs (reg_1dcnn, obj_1dcnn, size_1dcnn): none given")
    out = []
    for name, net in nets:
        net = copy.deepcopy(net).double().eval()
        for p in net.parameters():
            p.requires_grad_(False)
        out.append((name, net))
    return out


def _bn_terms(nets, x: torch.Tensor, detail: bool = False):
    """Sum over networks and layers of mean z**2 + mean log-variance-ratio**2 (and per-layer distances).

    Each network runs its own ``features`` on ``x`` (shape (n, 9, 128)); a hook on every BatchNorm1d takes its input
    (differentiably) and compares its moments over batch and time with the layer's running statistics.
    """
    total = x.new_zeros(())
    rows = []
    for name, net in nets:
        inputs = {}
        layers = {n: m for n, m in net.named_modules() if isinstance(m, nn.BatchNorm1d)}
        hooks = [m.register_forward_pre_hook(lambda _m, a, n=n: inputs.__setitem__(n, a[0])) for n, m in layers.items()]
        try:
            net.features(x.reshape(len(x), 3, 3, -1))
        finally:
            for h in hooks:
                h.remove()
        for layer, bn in layers.items():
            v = inputs[layer]
            mu, var = v.mean(dim=(0, 2)), v.var(dim=(0, 2), unbiased=False)
            z = (mu - bn.running_mean) / bn.running_var.sqrt()
            lr = torch.log(var.clamp_min(1e-30) / bn.running_var)
            total = total + (z ** 2).mean() + (lr ** 2).mean()
            if detail:
                rows.append({"network": name, "layer": layer, "median_abs_z": float(z.abs().median()),
                             "mean_log_var_ratio": float(lr.mean())})
    return (total, rows) if detail else total


def invert_mean_capture(checkpoints, histograms, *, captures: int = 400, smooth: float = 1.0,
                        iterations: int = 80, seed: int = 0) -> dict:
    """Fit the mean capture that brings DENALI's networks' BatchNorm inputs to their real running statistics.

    Parameters
    ----------
    checkpoints : sequence of DenaliCheckpoint
        The 1D CNNs among them are used (the MLP has no BatchNorm).
    histograms : ndarray, shape (N, 3, 3, 128)
        Simulated captures (counts): their mean is the start and the model's mean capture, their variation
        around it is kept.
    captures : int
        Captures drawn (without replacement, ``seed``) for the fit's variation; all of them if fewer.
    smooth : float
        Weight of the smoothness penalty (sum of squared second differences of ``log m``).
    iterations : int
        L-BFGS iterations (strong Wolfe line search).
    seed : int

    Returns
    -------
    dict
        ``mean_real`` and ``mean_model`` (lists, (9, 128) counts per bin), ``zones_real`` and ``zones_model``
        (:func:`zone_summary`), ``bn_before`` and ``bn_after`` (per network and layer: ``median_abs_z``,
        ``mean_log_var_ratio``), ``loss_before``, ``loss_after``, ``captures``, ``smooth``, ``iterations``,
        ``seconds``.

    Raises
    ------
    UserError
        Histograms of another shape, fewer than 2 captures, no 1D CNN, or bad fit settings.
    """
    x_all = np.asarray(histograms, dtype=np.float64)
    if x_all.ndim != 4 or x_all.shape[1:] != (3, 3, 128):
        raise UserError(f"DENALI's networks take (N, 3, 3, 128) histograms, got {x_all.shape}")
    if len(x_all) < 2 or not np.isfinite(x_all).all():
        raise UserError("the inversion needs at least 2 finite captures")
    if captures < 2 or iterations < 1 or not smooth >= 0:
        raise UserError(f"captures >= 2, iterations >= 1 and smooth >= 0 are needed (got {captures}, {iterations}, "
                        f"{smooth})")
    t0 = time.perf_counter()
    nets = _cnns(checkpoints)
    x_all = x_all.reshape(len(x_all), 9, 128)
    m_model = x_all.mean(axis=0)
    rng = np.random.default_rng(seed)
    pick = rng.choice(len(x_all), min(captures, len(x_all)), replace=False)
    dev = torch.from_numpy(x_all[pick] - m_model)
    log_m = torch.tensor(np.log(np.clip(m_model, 1.0, None)), requires_grad=True)
    weight = float(smooth)

    def objective():
        d2 = log_m[:, 2:] - 2 * log_m[:, 1:-1] + log_m[:, :-2]
        return _bn_terms(nets, torch.exp(log_m) + dev) + weight * (d2 ** 2).sum()

    with torch.no_grad():
        loss0, before = _bn_terms(nets, torch.from_numpy(m_model) + dev, detail=True)
    opt = torch.optim.LBFGS([log_m], lr=1, max_iter=int(iterations), history_size=30, line_search_fn="strong_wolfe")

    def closure():
        opt.zero_grad()
        loss = objective()
        loss.backward()
        return loss

    opt.step(closure)
    with torch.no_grad():
        m_real = torch.exp(log_m).numpy()
        loss1, after = _bn_terms(nets, torch.from_numpy(m_real) + dev, detail=True)
    return {"mean_real": m_real.tolist(), "mean_model": m_model.tolist(), "zones_real": zone_summary(m_real),
            "zones_model": zone_summary(m_model), "bn_before": before, "bn_after": after,
            "loss_before": float(loss0), "loss_after": float(loss1), "captures": int(len(pick)),
            "smooth": weight, "iterations": int(iterations), "seconds": time.perf_counter() - t0}
