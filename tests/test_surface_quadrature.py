"""Surface quadrature: exact areas, points on the surface, O(1/n) convergence on any triangulation."""

import numpy as np
import pytest

from nlosplan.errors import UserError
from nlosplan.simulators import Mesh, sample_surface, square_patch, surface_quadrature
from nlosplan.simulators.presets import object_mesh


def disc_fan(n_seg=64, r=0.1):
    """A disc triangulated as a fan: long sliver faces that defeat per-face quadrature."""
    a = np.linspace(0, 2 * np.pi, n_seg, endpoint=False)
    v = np.vstack([[0.0, 0.0, 0.0], np.stack([r * np.cos(a), r * np.sin(a), 0 * a], 1)])
    f = np.array([[0, 1 + i, 1 + (i + 1) % n_seg] for i in range(n_seg)])
    return Mesh(v, f, name="disc")


def integrand(p):
    return np.exp(8 * p[:, 0]) * (1 + 30 * p[:, 1] ** 2)


def exact_on(mesh):
    # midpoint rule on ~10^5 pieces under 0.6 mm: converged far below the tested errors
    from nlosplan.simulators.meshes import _fine_cells

    c, a, _ = _fine_cells(mesh, mesh.face_areas > 0, 6e-4, 4e-7, 2_000_000)
    return float(np.sum(integrand(c) * a))


@pytest.mark.parametrize("name", ["A", "circle", "8", "S"])
def test_areas_sum_exactly_and_points_lie_on_the_surface(name):
    mesh = object_mesh(name, "8in")
    q = surface_quadrature(mesh, 300)
    assert q.areas.sum() == pytest.approx(mesh.area, rel=1e-12)
    assert abs(len(q) - 300) <= 12
    tri = mesh.triangles[q.face_index]
    n = mesh.face_normals[q.face_index]
    assert np.abs(np.einsum("ij,ij->i", q.points - tri[:, 0], n)).max() < 1e-12
    assert np.allclose(np.linalg.norm(q.normals, axis=1), 1.0)


def test_converges_faster_than_random_samples_on_a_sliver_fan():
    disc = disc_fan()
    ref = exact_on(disc)
    errs_q, errs_r = [], []
    for n in (64, 256, 1024):
        q = surface_quadrature(disc, n, seed=1)
        errs_q.append(abs(np.sum(integrand(q.points) * q.areas) / ref - 1))
        r = [abs(np.sum(integrand(s.points) * s.areas) / ref - 1)
             for s in (sample_surface(disc, n, seed=k) for k in range(20))]
        errs_r.append(float(np.sqrt(np.mean(np.square(r)))))
    assert errs_q[0] < 3e-3 and errs_q[-1] < errs_q[0] / 4  # 16x more points, > 4x smaller error
    assert all(eq < er for eq, er in zip(errs_q, errs_r)), (errs_q, errs_r)  # beats stratified random


def test_face_mask_degenerate_faces_and_bad_input():
    patch = square_patch(0.1)
    v = np.vstack([patch.vertices, [[0.0, 0.0, 0.0]]])
    f = np.vstack([patch.faces, [[0, 0, 1], [4, 4, 4]]])  # two zero-area faces
    q = surface_quadrature(Mesh(v, f), 50)
    assert set(q.face_index.tolist()) <= {0, 1} and q.areas.sum() == pytest.approx(0.01)
    only = surface_quadrature(Mesh(v, f), 50, face_mask=np.array([True, False, False, False]))
    assert set(only.face_index.tolist()) == {0} and only.areas.sum() == pytest.approx(0.005)
    assert len(surface_quadrature(patch, 0)) == 0
    with pytest.raises(UserError, match="n=-1"):
        surface_quadrature(patch, -1)


def test_normals_never_average_front_and_side():
    mesh = object_mesh("A", "8in")
    q = surface_quadrature(mesh, 200)
    # each point's normal equals the normal of the face it sits on, within the 20 deg grouping
    cos = np.einsum("ij,ij->i", q.normals, mesh.face_normals[q.face_index])
    assert cos.min() > np.cos(np.radians(25))


def test_quadratures_are_kept_on_disk_for_the_next_process(tmp_path, monkeypatch):
    """A quadrature is written to $NLOSPLAN_CACHE/quadrature once and read back equal; a torn file is computed again."""
    from nlosplan.simulators import meshes

    monkeypatch.setenv("NLOSPLAN_CACHE", str(tmp_path))
    monkeypatch.setattr(meshes, "_QUADRATURES", {})
    mesh = object_mesh("S", "4in")
    first = surface_quadrature(mesh, 97)
    files = sorted((tmp_path / "quadrature").glob("*.npz"))
    assert len(files) == 1 and not list((tmp_path / "quadrature").glob(".*"))  # no temporary file left
    calls = []
    monkeypatch.setattr(meshes, "_quadrature", lambda *a: calls.append(a) or pytest.fail("computed again"))
    monkeypatch.setattr(meshes, "_QUADRATURES", {})  # a new process: only the disk has it
    again = surface_quadrature(mesh, 97)
    for name in ("points", "normals", "areas", "face_index"):
        np.testing.assert_array_equal(getattr(again, name), getattr(first, name))
        assert not getattr(again, name).flags.writeable
    monkeypatch.undo()
    monkeypatch.setenv("NLOSPLAN_CACHE", str(tmp_path))
    monkeypatch.setattr(meshes, "_QUADRATURES", {})
    surface_quadrature(mesh, 98)  # another point count: another file
    assert len(list((tmp_path / "quadrature").glob("*.npz"))) == 2
    files[0].write_bytes(files[0].read_bytes()[:100])  # torn by a crash
    monkeypatch.setattr(meshes, "_QUADRATURES", {})
    redone = surface_quadrature(mesh, 97)
    np.testing.assert_array_equal(redone.points, first.points)
    assert meshes._load_quadrature(files[0]) is not None  # written whole again


def test_an_unwritable_quadrature_cache_costs_time_not_the_result(tmp_path, monkeypatch):
    from nlosplan.simulators import meshes

    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    monkeypatch.setenv("NLOSPLAN_CACHE", str(blocker))  # $NLOSPLAN_CACHE/quadrature cannot be made
    monkeypatch.setattr(meshes, "_QUADRATURES", {})
    q = surface_quadrature(object_mesh("A", "4in"), 50)
    assert q.areas.sum() == pytest.approx(object_mesh("A", "4in").area, rel=1e-12)
