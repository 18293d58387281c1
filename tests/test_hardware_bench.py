"""``bench rig``: figures are measured, consistent with each other, and the CLI prints them."""

import json

import pytest

from nlosplan.cli import main
from nlosplan.hardware.bench import BITS_PER_BYTE, bench_rig, frame_text
from nlosplan.hardware.tmf8828_protocol import FrameAssembler, ZoneMode


def test_bench_rig_figures_are_consistent():
    res = bench_rig(frames_3x3=12, frames_8x8=5, seconds=0.1, end_to_end=False)
    f3, f8 = res["per_frame"]
    assert (f3["zones"], f3["frames"], f8["zones"], f8["frames"]) == ("3x3", 12, "8x8", 5)
    for f in (f3, f8):
        assert 0 < f["parse_ms_median"] and 0 < f["store_ms_median"]
        assert f["total_ms_median"] <= f["total_ms_p95"]
        assert f["line_time_ms"] == pytest.approx(f["bytes_per_frame"] * BITS_PER_BYTE / 2_000_000 * 1e3)
    # an 8x8 frame is 8 dumps + 4 results: about 8x the bytes of a 3x3 frame
    assert 7 < f8["bytes_per_frame"] / f3["bytes_per_frame"] < 9
    for p in res["parser"]:
        assert p["dropped_frames"] == 0 and p["times_line_rate"] == pytest.approx(p["bytes_per_second"] / 200_000)
    assert res["targets"]["met_3x3"] == (f3["total_ms_median"] <= 5.0)


def test_frame_text_parses_back():
    import numpy as np

    counts = np.arange(9 * 128).reshape(3, 3, 128)
    asm = FrameAssembler("3x3")
    (frame,) = [f for ln in frame_text(counts, ZoneMode.Z3X3) for f in asm.feed(ln)]
    np.testing.assert_array_equal(frame.counts, counts)


def test_cli_bench_rig_json(capsys):
    assert main(["bench", "rig", "--frames", "10", "--seconds", "0.05", "--no-pty", "--synchronous", "NORMAL",
                 "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["per_frame"][0]["synchronous"] == "NORMAL" and "end_to_end" not in data
