"""Batches over positions, objects and sensors give what separate runs give."""

import numpy as np
import pytest

from nlosplan.errors import UserError
from nlosplan.sensor_models import preset
from nlosplan.simulators import FastSimulator, Fidelity, corner_scene, denali_scene

FID = Fidelity(zone_sub=3, flash_sub=3, flash_outer=3, object_samples=128)
S3 = preset("tmf8828-3x3-short")


def test_mixed_objects_in_one_batch_equal_per_object_batches():
    pairs = {o: [denali_scene(o, "8in", p) for p in (4, 61)] for o in ("A", "circle", "7")}
    mixed = FastSimulator(sum(pairs.values(), []), S3, fidelity=FID).expected()
    per = np.concatenate([FastSimulator(v, S3, fidelity=FID).expected() for v in pairs.values()])
    assert mixed.shape == (6, 3, 3, 128)
    np.testing.assert_allclose(mixed, per, rtol=1e-5, atol=1e-6 * per.max())


def test_chunked_batch_equals_one_call():
    scenes = [denali_scene("S", "4in", p) for p in range(7)]
    a = FastSimulator(scenes, S3, fidelity=FID, chunk=3).expected()
    b = FastSimulator(scenes, S3, fidelity=FID, chunk=10).expected()
    np.testing.assert_allclose(a, b, rtol=1e-6)


def test_chunks_on_threads_equal_one_thread_in_order_with_progress():
    scenes = [denali_scene("S", "4in", p, albedo=0.36, diffuse_albedo=0.2) for p in range(0, 70, 10)]
    one = FastSimulator(scenes, S3, fidelity=FID, chunk=2, threads=1).expected()
    sim = FastSimulator(scenes, S3, fidelity=FID, chunk=2, threads=3)
    steps = []
    first = sim.expected(progress=lambda done, total: steps.append((done, total)))
    again = sim.expected(parts=True)["counts"]  # warm now: every chunk on the pool
    assert steps == [(2, 7), (4, 7), (6, 7), (7, 7)]
    assert np.abs(one).max() > 0 and len({float(x.sum()) for x in one}) == 7  # seven different scenes
    np.testing.assert_array_equal(first, one)
    np.testing.assert_array_equal(again, one)


def test_thread_count_from_the_environment(monkeypatch):
    from nlosplan.planner.design.workers import init_worker
    from nlosplan.resources import THREADS_ENV, default_threads

    monkeypatch.setenv(THREADS_ENV, "3")
    assert default_threads() == 3 and FastSimulator(denali_scene(), S3, fidelity=FID).threads == 3
    for bad, msg in (("two", "is not a whole number"), ("0", "at least 1 thread")):
        monkeypatch.setenv(THREADS_ENV, bad)
        with pytest.raises(UserError, match=f"{THREADS_ENV}='{bad}'.*{msg}"):
            default_threads()
    monkeypatch.delenv(THREADS_ENV)
    monkeypatch.setattr("os.sched_getaffinity", lambda pid: {0, 1, 5})
    assert default_threads() == 3
    with pytest.raises(UserError, match="threads=0: at least 1"):
        FastSimulator(denali_scene(), S3, fidelity=FID, threads=0)
    monkeypatch.setattr("threadpoolctl.threadpool_limits", lambda n: None)  # keep this test process's threads
    monkeypatch.setattr("torch.set_num_threads", lambda n: None)
    monkeypatch.setenv("OMP_NUM_THREADS", "")
    monkeypatch.delenv("OMP_NUM_THREADS")  # restored after the test, like THREADS_ENV
    init_worker()  # a design worker: one thread (the pool runs one worker per core)
    assert default_threads() == 1


def test_batch_over_sensors_equals_separate_sensors():
    scene = denali_scene("A", "8in", 19, lights="on")
    sensors = [S3.replace(jitter_fwhm_ps=j, photon_scale=k) for j, k in ((0.0, 2.0), (150.0, 1.0), (400.0, 3.0))]
    batch = FastSimulator(scene, None, sensors=sensors, fidelity=FID).expected()
    assert batch.shape == (3, 3, 3, 128)
    for s, b in zip(sensors, batch):
        np.testing.assert_allclose(b, FastSimulator(scene, s, fidelity=FID).expected(), rtol=2e-5, atol=1e-3)


def test_incompatible_batches_are_refused():
    with pytest.raises(UserError, match="reflectance"):
        FastSimulator([denali_scene(), denali_scene(reflectance="lambertian")], S3)
    with pytest.raises(UserError, match="rig"):
        FastSimulator([denali_scene(), corner_scene(reflectance="retroreflective")], S3)
    with pytest.raises(UserError, match="may differ only in"):
        FastSimulator(denali_scene(), None, sensors=[S3, S3.replace(n_bins=64)])
    for field, value in (("bin_width_ps", 1.05 * S3.bin_width_ps), ("start_offset_ps", S3.start_offset_ps + 50.0)):
        with pytest.raises(UserError, match=f"share their time base; {field} differs"):
            FastSimulator(denali_scene(), None, sensors=[S3, S3.replace(**{field: value})])


def test_near_wall_couplings_computed_for_the_batch_equal_scene_by_scene(monkeypatch):
    # DENALI's mount and plate have near-wall blocks: their exact couplings are computed for the batch's scenes at
    # once (transport.with_exact_couplings) and must give the histograms of computing them in each scene's step
    import nlosplan.simulators.fast.simulator as simulator
    from nlosplan.simulators.fast import transport

    scenes = [denali_scene(o, "8in", p, albedo=0.36, diffuse_albedo=0.2, mount=True, mount_in_background=False)
              for o, p in (("A", 3), ("S", 40), ("circle", 77))]
    sim = FastSimulator(scenes, S3, fidelity=FID, share=False)
    static = sim.plan.static
    near = [k for k, st in enumerate(static.objects) if st.near1 or st.near2]
    assert near  # the supports come within a few cells of the wall
    chunk_p, _ = sim._chunk_params()[0]
    added = transport.with_exact_couplings(static, sim._arrays, chunk_p)
    for k in near:
        st, p = static.objects[k], added["objects"][k]
        for leg, n_near in (("1", st.near1), ("2", st.near2)):
            if n_near:
                assert p[f"exact{leg}"].shape == (len(p["areas"]), p["areas"].shape[1], n_near)
    batched = sim.expected(parts=True)
    calls = []
    monkeypatch.setattr(simulator, "with_exact_couplings",
                        lambda static, arrays, scene_p, terms=None: calls.append(terms) or scene_p)
    simulator._BATCHED_TERMS.clear_cache()
    stepwise = FastSimulator(scenes, S3, fidelity=FID, share=False).expected(parts=True)
    simulator._BATCHED_TERMS.clear_cache()  # later tests trace the batched couplings again
    assert calls and np.abs(batched["object"]).max() > 0
    for part in ("counts", "object"):
        np.testing.assert_array_equal(batched[part], stepwise[part])
