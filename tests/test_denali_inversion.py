"""The mean capture recovered from DENALI's networks' BatchNorm statistics: it finds a known mean capture, and
says what it was given before any work."""

import copy
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from nlosplan.errors import UserError
from nlosplan.tasks.denali_checkpoints import load_denali_checkpoint
from nlosplan.tasks.denali_inversion import invert_mean_capture, zone_summary

pytestmark = pytest.mark.usefixtures("one_torch_thread")
CKPT = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "denali" / "checkpoints" / "reg_1dcnn.pth"
T = np.arange(128.0)


def _mean(peak_bin, sigma, height, floor):
    """(9, 128): per zone a Gaussian direct return (peak bin and sigma per zone, height x 0.6..1.4) on a floor."""
    peak_bin, sigma = np.broadcast_to(peak_bin, 9)[:, None], np.broadcast_to(sigma, 9)[:, None]
    zone_scale = np.linspace(0.6, 1.4, 9)[:, None]
    return floor + zone_scale * height * np.exp(-0.5 * ((T - peak_bin) / sigma) ** 2)


def _with_running_stats_of(net, x):
    """A copy of ``net`` whose BatchNorm layers keep the statistics of inputs ``x`` (set layer by layer, as the
    layers before each normalise by their new statistics)."""
    net = copy.deepcopy(net).double().eval()
    h = torch.from_numpy(x.reshape(len(x), 9, 128))
    with torch.no_grad():
        for conv, bn in ((net.conv1, net.bn1), (net.conv2, net.bn2), (net.conv3, net.bn3)):
            v = conv(h)
            bn.running_mean.copy_(v.mean(dim=(0, 2)))
            bn.running_var.copy_(v.var(dim=(0, 2), unbiased=False))
            h = torch.nn.functional.gelu(bn(v))
    return net.float()


def test_zone_summary_reads_peak_width_and_floors():
    m = _mean(60.0, 3.0, 20_000.0, 1000.0)
    m[:, :60] -= 700.0   # a floor of 300 before the peak
    s = zone_summary(m)
    assert [z["peak_bin"] for z in s] == [60] * 9
    assert s[4]["fwhm_bins"] == pytest.approx(2.3548 * 3.0, abs=0.25)
    assert s[0]["floor_before"] == pytest.approx(300.0) and s[8]["floor_after"] == pytest.approx(1000.0)
    assert s[4]["mean"] == pytest.approx(m[4].mean())
    assert zone_summary(_mean(5.0, 1.0, 1000.0, 10.0))[0]["floor_before"] is None   # no bins before: none, not NaN
    with pytest.raises(UserError, match="at least 16 bins"):
        zone_summary(np.ones((9, 8)))


@pytest.mark.slow   # three real networks, 60 L-BFGS steps: ~1-2 min on 2 cores
@pytest.mark.skipif(not CKPT.is_file(), reason="needs DENALI's real-trained checkpoints, test data beside the checkout "
                    "(../shared/data/denali/checkpoints); the package never ships them")
def test_inversion_recovers_what_it_can_of_a_known_mean_capture_through_the_real_networks():
    """Statistics set from captures with a known mean (columns 4 bins apart, widest on the left), the fit started
    from another (every zone at bin 50, narrow): it recovers the zones' relative timing (to about 2 bins) and
    which zones are brighter. Not identified (not asserted): the absolute time (BatchNorm pools over time), the
    widths (here 6.3-10.1 bins against 3.5-7.1, out of order) and how the level splits into peak and floor."""
    rng = np.random.default_rng(3)
    col = np.arange(9) % 3
    truth = _mean(60.0 - 4.0 * col, np.array([3.0, 2.0, 1.5])[col], 20_000.0, 900.0)
    model = _mean(np.full(9, 50.0), np.ones(9), 60_000.0, 1183.0)
    variation = rng.normal(0.0, 1.0, (64, 9, 128)) * np.sqrt(model)[None] * 0.2
    variation -= variation.mean(axis=0)
    nets = [SimpleNamespace(name=n, net=_with_running_stats_of(load_denali_checkpoint(CKPT.parent / f"{n}.pth", n).net,
                                                               truth[None] + variation))
            for n in ("reg_1dcnn", "obj_1dcnn", "size_1dcnn")]
    res = invert_mean_capture(nets, (model[None] + variation).reshape(-1, 3, 3, 128), captures=64, iterations=60)
    assert res["loss_after"] < 0.05 * res["loss_before"]
    peak = np.array([z["peak_bin"] for z in res["zones_real"]]).reshape(3, 3)
    assert (peak[:, 0] > peak[:, 1]).all() and (peak[:, 1] > peak[:, 2]).all()   # the columns' order in time
    assert np.abs(peak[:, 0] - peak[:, 2] - 8).max() <= 2                        # and their spread, to 2 bins
    level = np.array([z["mean"] for z in res["zones_real"]]).reshape(3, 3)
    assert (level[2] > level[0]).all()   # the brighter bottom row
    assert [z["peak_bin"] for z in res["zones_model"]] == [50] * 9   # the start, reported beside it
    assert {r["layer"] for r in res["bn_after"]} == {"bn1", "bn2", "bn3"}
    assert res["captures"] == 64


def test_bad_inputs_are_refused_in_one_line():
    net = SimpleNamespace(name="obj_mlp", net=torch.nn.Linear(2, 2))
    with pytest.raises(UserError, match=r"\(N, 3, 3, 128\)"):
        invert_mean_capture([net], np.ones((4, 9, 128)))
    with pytest.raises(UserError, match="1D CNNs"):
        invert_mean_capture([net], np.ones((4, 3, 3, 128)))
    with pytest.raises(UserError, match="iterations >= 1"):
        invert_mean_capture([net], np.ones((4, 3, 3, 128)), iterations=0)
