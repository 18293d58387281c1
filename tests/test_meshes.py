"""Mesh loading (OBJ), scene-type mesh validation, and surface sampling."""

from __future__ import annotations

from importlib import resources

import numpy as np
import pytest

from nlosplan.errors import UserError
from nlosplan.simulators.meshes import SurfaceSamples, load_obj, sample_surface, square_patch
from nlosplan.simulators.scene import Mesh

OBJECTS = resources.files("nlosplan.denali") / "data" / "objects"


def _signed_volume(mesh: Mesh) -> float:
    t = mesh.triangles
    return float(np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() / 6.0)


def _is_closed_and_oriented(mesh: Mesh) -> bool:
    """Every directed edge appears once and its reverse once (closed, consistently wound)."""
    f = mesh.faces
    directed = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    fwd = {tuple(e) for e in directed.tolist()}
    return len(fwd) == len(directed) and all((b, a) in fwd for a, b in fwd)


def _write_obj(path, vertices, faces) -> None:
    lines = [f"v {x} {y} {z}" for x, y, z in vertices] + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")


TETRA_V = [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)]
TETRA_OUT = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]


# ------------------------------------------------------------------ load_obj
def test_load_packaged_a8in_is_closed_outward_and_matches_trimesh():
    import trimesh

    with resources.as_file(OBJECTS / "A_8in.obj") as path:
        mesh = load_obj(path)
        ref = trimesh.load(path, force="mesh", process=True)
    assert mesh.name == "A_8in"
    assert _is_closed_and_oriented(mesh)
    assert _signed_volume(mesh) > 0
    assert _signed_volume(mesh) == pytest.approx(ref.volume, rel=1e-9)
    assert mesh.area == pytest.approx(ref.area, rel=1e-9)
    # outward: the face normals on the +z cap point +z, those on the -z cap point -z
    n, z = mesh.face_normals, mesh.triangles[:, :, 2].mean(axis=1)
    assert np.all(n[z > 0.0038, 2] > 0.99) and np.all(n[z < -0.0038, 2] < -0.99)


def test_load_flips_inward_watertight_mesh(tmp_path):
    path = tmp_path / "inside_out.obj"
    _write_obj(path, TETRA_V, [f[::-1] for f in TETRA_OUT])
    mesh = load_obj(path, name="tet")
    assert mesh.name == "tet"
    assert _signed_volume(mesh) == pytest.approx(1 / 6, rel=1e-12)
    assert mesh.area == pytest.approx(1.5 + np.sqrt(3) / 2, rel=1e-12)


def test_load_merges_duplicates_and_keeps_degenerate_faces(tmp_path):
    path = tmp_path / "deg.obj"
    _write_obj(path, [(0, 0, 0), (1, 0, 0), (0, 1, 0), (2, 0, 0), (0, 0, 0)], [(0, 1, 2), (4, 1, 3)])
    mesh = load_obj(path)
    assert mesh.vertices.shape == (4, 3)  # the duplicate origin is merged
    assert mesh.faces.shape == (2, 3)
    np.testing.assert_allclose(mesh.face_areas, [0.5, 0.0])


def _bad_file(d, kind):
    if kind == "missing":
        return d / "missing.obj"
    if kind == "directory":
        return d
    path = d / {"garbage": "garbage.obj", "binary": "bin.obj", "json": "x.json", "points": "pts.obj"}[kind]
    if kind == "binary":
        path.write_bytes(bytes(range(256)) * 4)
    else:
        path.write_text({"garbage": "hello\nnot a mesh\n", "json": "{}", "points": "v 0 0 0\nv 1 0 0\n"}[kind])
    return path


@pytest.mark.parametrize(
    "kind, words",
    [("missing", "does not exist"), ("directory", "is not a file"), ("garbage", "no triangles"),
     ("binary", "not a text OBJ"), ("json", "cannot be read"), ("points", "no triangles")],
)
def test_load_bad_files_raise_one_line(tmp_path, kind, words):
    path = _bad_file(tmp_path, kind)
    with pytest.raises(UserError) as err:
        load_obj(path)
    msg = str(err.value)
    assert "\n" not in msg and words in msg and path.name in msg


# ----------------------------------------------------- Mesh validation (scene types)
def test_mesh_with_nan_vertex_is_rejected():
    v = np.array([[0, 0, 0], [1, 0, 0], [np.nan, 1, 0]], dtype=float)
    with pytest.raises(UserError) as err:
        Mesh(vertices=v, faces=[[0, 1, 2]], name="bad")
    msg = str(err.value)
    assert "\n" not in msg and "vertex 2" in msg and "finite" in msg


@pytest.mark.parametrize(
    "vertices, faces, words",
    [(np.zeros((0, 3)), np.zeros((0, 3), dtype=int), "no vertices"),
     (np.eye(3), np.zeros((0, 3), dtype=int), "no triangles")],
)
def test_empty_mesh_is_rejected(vertices, faces, words):
    with pytest.raises(UserError) as err:
        Mesh(vertices=vertices, faces=faces, name="empty")
    assert "\n" not in str(err.value) and words in str(err.value)


# -------------------------------------------------------------- square_patch
def test_square_patch_geometry():
    m = square_patch(0.2)
    assert m.area == pytest.approx(0.04, rel=1e-15)
    np.testing.assert_allclose(m.face_normals, [[0, 0, 1], [0, 0, 1]])
    np.testing.assert_allclose(m.vertices.mean(axis=0), 0.0, atol=1e-15)
    np.testing.assert_allclose(np.ptp(m.vertices, axis=0), [0.2, 0.2, 0.0])
    with pytest.raises(UserError, match="patch size"):
        square_patch(0.0)


# ------------------------------------------------------------ sample_surface
@pytest.fixture(scope="module")
def letter() -> Mesh:
    with resources.as_file(OBJECTS / "A_8in.obj") as path:
        return load_obj(path)


def _barycentric(points, tri):
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    v0, v1, v2 = b - a, c - a, points - a
    d00, d01, d11 = (v0 * v0).sum(1), (v0 * v1).sum(1), (v1 * v1).sum(1)
    d20, d21 = (v2 * v0).sum(1), (v2 * v1).sum(1)
    den = d00 * d11 - d01 * d01
    v = (d11 * d20 - d01 * d21) / den
    w = (d00 * d21 - d01 * d20) / den
    return np.stack([1 - v - w, v, w], axis=1)


def test_samples_areas_sum_to_mesh_area(letter):
    s = sample_surface(letter, 5000, seed=3)
    assert isinstance(s, SurfaceSamples) and len(s) == 5000
    assert s.points.dtype == s.normals.dtype == s.areas.dtype == np.float64
    assert s.areas.sum() == pytest.approx(letter.area, rel=1e-12)
    np.testing.assert_allclose(s.areas, letter.area / 5000, rtol=1e-15)


def test_samples_lie_on_their_faces_with_face_normals(letter):
    s = sample_surface(letter, 4000, seed=1)
    tri = letter.triangles[s.face_index]
    bary = _barycentric(s.points, tri)
    assert np.all(bary >= -1e-9) and np.all(bary <= 1 + 1e-9)
    n = letter.face_normals[s.face_index]
    dist = np.abs(np.einsum("ij,ij->i", s.points - tri[:, 0], n))
    assert dist.max() < 1e-12
    np.testing.assert_array_equal(s.normals, n)
    np.testing.assert_allclose(np.linalg.norm(s.normals, axis=1), 1.0, rtol=1e-12)


def test_per_face_counts_follow_area(letter):
    n = 3000
    s = sample_surface(letter, n, seed=7)
    counts = np.bincount(s.face_index, minlength=letter.faces.shape[0])
    expected = n * letter.face_areas / letter.area
    assert np.abs(counts - expected).max() <= 2.0


def test_points_are_uniform_on_a_triangle():
    m = Mesh(vertices=[[0, 0, 0], [1, 0, 0], [0, 1, 0]], faces=[[0, 1, 2]])
    s = sample_surface(m, 20000, seed=0)
    np.testing.assert_allclose(s.points.mean(axis=0), [1 / 3, 1 / 3, 0], atol=5e-3)
    # the fraction below y = 0.5 is the area fraction 3/4
    assert np.mean(s.points[:, 1] < 0.5) == pytest.approx(0.75, abs=0.01)


def test_zero_area_faces_are_never_sampled():
    v = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0], [3, 0, 0], [1, 1, 0]]
    # face 1 is degenerate (collinear), face 3 repeats a vertex
    faces = [[0, 1, 2], [1, 3, 4], [1, 5, 2], [2, 2, 5]]
    m = Mesh(vertices=v, faces=faces)
    assert m.face_areas[1] == 0 and m.face_areas[3] == 0
    s = sample_surface(m, 10001, seed=5)
    assert set(np.unique(s.face_index).tolist()) == {0, 2}
    assert s.areas.sum() == pytest.approx(m.area, rel=1e-12)


def test_face_mask_restricts_sampling(letter):
    mask = letter.face_normals[:, 2] < -0.99  # the -z cap only
    s = sample_surface(letter, 2000, seed=2, face_mask=mask)
    assert np.all(mask[s.face_index])
    assert s.areas.sum() == pytest.approx(letter.face_areas[mask].sum(), rel=1e-12)
    np.testing.assert_allclose(s.normals[:, 2], -1.0, atol=1e-9)
    empty = sample_surface(letter, 100, face_mask=np.zeros(letter.faces.shape[0], dtype=bool))
    assert empty.points.shape == (0, 3) and empty.areas.shape == (0,)
    with pytest.raises(UserError, match="face_mask"):
        sample_surface(letter, 10, face_mask=np.ones(3, dtype=bool))


def test_sampling_is_deterministic_per_seed(letter):
    a = sample_surface(letter, 500, seed=11)
    b = sample_surface(letter, 500, seed=11)
    c = sample_surface(letter, 500, seed=12)
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.face_index, b.face_index)
    assert not np.array_equal(a.points, c.points)


def test_zero_and_negative_sample_counts(letter):
    s = sample_surface(letter, 0)
    assert s.points.shape == (0, 3) and s.normals.shape == (0, 3)
    assert s.areas.shape == (0,) and s.face_index.shape == (0,)
    with pytest.raises(UserError, match="n=-1"):
        sample_surface(letter, -1)
    with pytest.raises(UserError, match="integer"):
        sample_surface(letter, 2.5)
    with pytest.raises(UserError, match="needs a Mesh"):
        sample_surface(np.zeros((3, 3)), 10)


def test_sample_estimates_area_moment(letter):
    """Quadrature check: the first area moment (integral of x dA) matches the exact sum over faces."""
    t = letter.triangles
    # exact integral of the position over each triangle: area * centroid
    exact = (letter.face_areas[:, None] * t.mean(axis=1)).sum(axis=0)
    s = sample_surface(letter, 20000, seed=4)
    est = (s.areas[:, None] * s.points).sum(axis=0)
    # noise ~ A * sigma_x / sqrt(n) ~ 1.4e-5 m^3 for iid sampling; strata make it smaller
    np.testing.assert_allclose(est, exact, rtol=0, atol=1e-5)
