"""The design planner's reference cache by content (issue 20): a second run does not simulate again."""

import numpy as np
import pytest

from nlosplan.planner.design import data as design_data
from nlosplan.planner.design import reference_cache
from nlosplan.planner.design.data import SceneSet, load_reference
from nlosplan.planner.design.evaluators import DEFAULT_FIDELITY
from nlosplan.planner.design.run import EVALUATIONS, DesignConfig, read_evaluations, run_design
from nlosplan.planner.design.search import SearchConfig
from nlosplan.planner.design.space import DesignSpace
from nlosplan.planner.design.worlds import WorldsConfig


def tiny() -> DesignConfig:
    fid = {k: dict(v) for k, v in DEFAULT_FIDELITY.items()}
    fid["bound"]["draws"] = 30
    fid["trained"].update(epochs=2, bootstrap=20)
    return DesignConfig(
        space=DesignSpace(zones=((1, 1), (3, 3)), bin_factors=(1,), axes=("zones",)),
        search=SearchConfig(grid_points=2, refine_steps=0, seeds=1, candidates=1, optimize_evals=2, fidelity=fid),
        scenes=SceneSet(objects=("A", "S"), positions=tuple(range(0, 100, 25)), repeats=1,
                        crlb_objects=("A",), crlb_stride=50, fidelity="draft"),
        worlds=WorldsConfig(count=1, candidates=1), label="cache")


@pytest.fixture
def counted(monkeypatch, tmp_path):
    monkeypatch.setenv("NLOSPLAN_CACHE", str(tmp_path / "cache"))
    calls = []
    real = design_data.simulate_reference

    def counting(sensor, scenes, **kw):
        calls.append(sensor.name)
        return real(sensor, scenes, **kw)

    monkeypatch.setattr(design_data, "simulate_reference", counting)
    return calls


def _values(out):
    return sorted((r["design_id"] if "design_id" in r else str(r.get("design")), r.get("kind"), r.get("task"),
                   r.get("value")) for r in read_evaluations(out / EVALUATIONS))


def _means(out):
    (path,) = sorted((out / "reference").glob("1x1_*.npz"))
    return load_reference(path).means


@pytest.mark.slow  # two design runs and the start of a third (~2 min on 2 shared cores); the damaged-entry test covers reuse fast
def test_second_run_takes_the_references_from_the_cache(counted, tmp_path):
    run_design(tiny(), tmp_path / "a", workers=1)
    n = len(counted)
    assert n >= 1
    run_design(tiny(), tmp_path / "b", workers=1)
    assert len(counted) == n, "the second run simulated references again"
    np.testing.assert_array_equal(_means(tmp_path / "a"), _means(tmp_path / "b"))
    assert _values(tmp_path / "a") == _values(tmp_path / "b")
    # --no-cache simulates again (stopped at its first reference: the rest of the run is the runs' above)
    real = design_data.simulate_reference

    def first_then_stop(sensor, scenes, **kw):
        real(sensor, scenes, **kw)
        raise _Stop

    design_data.simulate_reference = first_then_stop
    with pytest.raises(RuntimeError, match="reference failed: _Stop"):   # the run names the failed reference
        run_design(tiny(), tmp_path / "c", workers=1, cache=False)
    assert len(counted) == n + 1


class _Stop(Exception):
    """Ends a design run once it has simulated a reference."""


def test_damaged_entry_is_recomputed_with_a_note(counted, tmp_path):
    """The run's reference step (``run._simulate``) on one small layout: stored, damaged, recomputed, trusted again."""
    from nlosplan.planner.design.executors import SerialExecutor
    from nlosplan.planner.design.jobs import ReferenceJob
    from nlosplan.planner.design.run import _simulate
    from nlosplan.sensor_models.presets import preset

    sensor = preset("tmf8828-3x3-short").replace(zones_rows=1, zones_cols=1)
    scenes = SceneSet(objects=("A",), positions=(0, 50), repeats=1, crlb_objects=(), fidelity="draft")
    notes = []

    def step(folder):
        path = tmp_path / folder / "1x1.npz"
        path.parent.mkdir()
        _simulate(SerialExecutor(), [ReferenceJob(str(path), sensor, scenes, "1x1")],
                  lambda text, *a: notes.append(text), "references")
        return load_reference(path).means

    first = step("a")
    assert len(counted) == 1 and first.shape == (2 * 2, 1, 1, 128) and first.sum() > 0
    (entry,) = sorted(reference_cache.cache_dir().glob("*.npz"))
    raw = bytearray(entry.read_bytes())
    raw[len(raw) // 2] ^= 0xFF
    entry.write_bytes(bytes(raw))
    again = step("b")
    assert len(counted) == 2
    assert any("damaged" in n and "checksum" in n for n in notes), notes
    np.testing.assert_array_equal(first, again)
    # the recomputed entry is valid again: a third run takes it
    np.testing.assert_array_equal(step("c"), first)
    assert len(counted) == 2


def test_key_changes_with_sensor_scenes_and_code(monkeypatch):
    cfg = tiny()
    sensor = cfg.space.sensor
    k = reference_cache.cache_key(sensor, cfg.scenes)
    assert k == reference_cache.cache_key(sensor, cfg.scenes)
    assert k != reference_cache.cache_key(sensor.replace(jitter_fwhm_ps=sensor.jitter_fwhm_ps + 1.0), cfg.scenes)
    from dataclasses import replace
    assert k != reference_cache.cache_key(sensor, replace(cfg.scenes, fidelity="low"))
    monkeypatch.setattr(reference_cache, "code_version", lambda: "edited")
    assert k != reference_cache.cache_key(sensor, cfg.scenes)
    # the compiled deposit kernel's source is code the references depend on
    names = [f.name for f in reference_cache.code_files()]
    assert "deposit.cc" in names and "transport.py" in names and "bounds.py" in names
