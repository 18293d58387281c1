"""Triangle-mesh input and area-weighted surface sampling.

:func:`load_obj` reads a mesh file into a validated :class:`~nlosplan.simulators.scene.Mesh`
(``trimesh`` is imported only when a file is read). :func:`sample_surface`
draws stratified, area-weighted points on a mesh for quadrature of surface
integrals such as the three-bounce transport over a hidden object.

Notes
-----
With ``M`` samples of equal area weight ``A / M`` (``A`` the sampled area),
a surface integral is estimated as

    integral_S f(x) dA  ~=  sum_k f(p_k) * areas_k

The strata make the per-face sample counts differ from their expectation
``M a_f / A`` by less than one, so the estimator's variance is far below
that of independent sampling for smooth ``f``.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nlosplan.errors import UserError
from nlosplan.simulators.scene import Mesh

__all__ = ["SurfaceSamples", "load_obj", "sample_surface", "square_patch"]


def load_obj(path: str | os.PathLike, *, name: str | None = None) -> Mesh:
    """Load a triangle mesh file (Wavefront OBJ or another format trimesh reads).

    Parameters
    ----------
    path : str or path-like
        Mesh file; coordinates are taken as metres.
    name : str, optional
        Mesh label; defaults to the file name without its suffix.

    Returns
    -------
    Mesh
        Vertices at the same position merged (texture coordinates and
        vertex normals are dropped); degenerate (zero-area) faces kept. A
        watertight mesh with inward-facing winding (negative signed volume)
        is flipped so that its face normals point outward.

    Raises
    ------
    UserError
        The file is missing or unreadable, is not a mesh, or has no triangles
        (one line naming the file).
    """
    p = Path(path)
    label = name if name is not None else p.stem
    if not p.exists():
        raise UserError(f"mesh file {str(p)!r} does not exist")
    if not p.is_file():
        raise UserError(f"mesh file {str(p)!r} is not a file")
    if p.suffix.lower() == ".obj":
        try:
            p.read_bytes().decode("utf-8")
        except OSError as e:
            raise UserError(f"mesh file {str(p)!r} cannot be read: {e.strerror or e}") from None
        except UnicodeDecodeError:
            raise UserError(f"mesh file {str(p)!r} is not a text OBJ file (not UTF-8)") from None

    import trimesh  # heavy import, only when a file is read

    try:
        tm = trimesh.load(str(p), force="mesh", process=True)
    except Exception as e:  # trimesh raises many types for bad files
        msg = " ".join(str(e).split()) or type(e).__name__
        raise UserError(f"mesh file {str(p)!r} cannot be read as a mesh: {msg}") from None
    if not isinstance(tm, trimesh.Trimesh):
        raise UserError(f"mesh file {str(p)!r} does not hold a triangle mesh")
    if len(tm.faces) == 0:
        raise UserError(f"mesh file {str(p)!r} has no triangles")
    # only positions are kept, so also merge vertices that differ only in texture or normal
    tm.merge_vertices(merge_tex=True, merge_norm=True)
    vertices = np.asarray(tm.vertices, dtype=np.float64)
    faces = np.asarray(tm.faces, dtype=np.int64)
    if tm.is_watertight and float(tm.volume) < 0:
        faces = faces[:, ::-1].copy()
    return Mesh(vertices=vertices, faces=faces, name=label)


@dataclass(frozen=True, eq=False)
class SurfaceSamples:
    """Points on a mesh surface with their quadrature weights.

    Parameters
    ----------
    points : ndarray of float64, shape (M, 3)
        Sample positions in the mesh frame, metres.
    normals : ndarray of float64, shape (M, 3)
        Unit outward normal of the face each sample lies on.
    areas : ndarray of float64, shape (M,)
        Area represented by each sample, m^2; they sum to the sampled area.
    face_index : ndarray of int64, shape (M,)
        Index of the face each sample lies on.
    """

    points: np.ndarray
    normals: np.ndarray
    areas: np.ndarray
    face_index: np.ndarray

    def __len__(self) -> int:
        return int(self.areas.shape[0])


def _empty() -> SurfaceSamples:
    return SurfaceSamples(
        points=np.zeros((0, 3)), normals=np.zeros((0, 3)), areas=np.zeros(0),
        face_index=np.zeros(0, dtype=np.int64),
    )


def sample_surface(mesh: Mesh, n: int, *, seed: int = 0, face_mask: np.ndarray | None = None) -> SurfaceSamples:
    """Stratified, area-weighted samples on a mesh surface.

    Parameters
    ----------
    mesh : Mesh
        The surface, in its own frame (metres).
    n : int
        Number of samples (>= 0).
    seed : int
        Seed of :func:`numpy.random.default_rng`; the result is a pure
        function of ``(mesh, n, seed, face_mask)``.
    face_mask : array_like of bool, shape (F,), optional
        Sample only the faces where this is true.

    Returns
    -------
    SurfaceSamples
        ``n`` samples, each with area ``A / n`` (``A`` the total area of
        the selected faces); empty when ``n == 0`` or ``A == 0``.

    Raises
    ------
    UserError
        ``mesh`` not a :class:`Mesh`, ``n`` negative or not an integer, or
        ``face_mask`` not boolean of shape (F,).

    Notes
    -----
    Stratum ``k`` draws ``u_k = (k + xi_k) / n`` and picks the face whose
    interval of the cumulative area contains ``u_k A`` (zero-area faces have
    empty intervals and are never picked). The position inside that
    interval, rescaled to [0, 1), is the first uniform number ``r1``; with a
    second independent uniform ``r2`` the point is

        p = (1 - sqrt(r1)) a + sqrt(r1) (1 - r2) b + sqrt(r1) r2 c

    for the face's vertices ``a, b, c``, which is uniform on the triangle.
    """
    if not isinstance(mesh, Mesh):
        raise UserError(f"sample_surface needs a Mesh, got {type(mesh).__name__}")
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)):
        raise UserError(f"number of surface samples n={n!r} must be an integer >= 0")
    n = int(n)
    if n < 0:
        raise UserError(f"number of surface samples n={n} must be >= 0")
    face_areas = mesh.face_areas
    if face_mask is not None:
        mask = np.asarray(face_mask)
        if mask.shape != face_areas.shape or mask.dtype != np.bool_:
            raise UserError(
                f"face_mask must be a boolean array of shape ({face_areas.shape[0]},), got "
                f"{mask.dtype} of shape {mask.shape}"
            )
        face_areas = np.where(mask, face_areas, 0.0)
    cum = np.cumsum(face_areas)
    total = float(cum[-1])
    if n == 0 or total <= 0:
        return _empty()

    rng = np.random.default_rng(seed)
    xi = rng.random(n)
    r2 = rng.random(n)
    target = (np.arange(n) + xi) / n * total
    idx = np.searchsorted(cum, target, side="right")
    last = int(np.flatnonzero(face_areas > 0)[-1])
    idx = np.minimum(idx, last)  # guards u*A rounding up to A
    a_sel = face_areas[idx]
    start = cum[idx] - a_sel
    r1 = np.clip((target - start) / a_sel, 0.0, 1.0)

    tri = mesh.triangles[idx]
    s = np.sqrt(r1)[:, None]
    r2 = r2[:, None]
    points = (1.0 - s) * tri[:, 0] + s * (1.0 - r2) * tri[:, 1] + s * r2 * tri[:, 2]
    return SurfaceSamples(
        points=points,
        normals=mesh.face_normals[idx],
        areas=np.full(n, total / n),
        face_index=idx.astype(np.int64),
    )


def square_patch(size: float, name: str = "patch") -> Mesh:
    """A flat square of two triangles in the z = 0 plane, centred at the origin.

    Parameters
    ----------
    size : float
        Side length, metres (> 0).
    name : str
        Mesh label.

    Returns
    -------
    Mesh
        Four vertices, two faces, normal +z (counter-clockwise seen from +z).
    """
    if isinstance(size, bool) or not isinstance(size, (int, float, np.integer, np.floating)) or not (
        np.isfinite(size) and size > 0
    ):
        raise UserError(f"patch size={size!r} must be a finite length > 0 (metres)")
    h = float(size) / 2.0
    vertices = np.array([[-h, -h, 0.0], [h, -h, 0.0], [h, h, 0.0], [-h, h, 0.0]])
    faces = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int64)
    return Mesh(vertices=vertices, faces=faces, name=name)


def _morton_order(points: np.ndarray) -> np.ndarray:
    """Indices ordering 3-D points along a Morton (Z-order) curve: neighbours in order are near in space."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    q = ((points - lo) / np.maximum(hi - lo, 1e-12) * 1023).astype(np.uint64)
    code = np.zeros(len(points), dtype=np.uint64)
    for bit in range(10):
        for axis in range(3):
            code |= ((q[:, axis] >> np.uint64(bit)) & np.uint64(1)) << np.uint64(3 * bit + axis)
    return np.argsort(code, kind="stable")


def _normal_bins(normals: np.ndarray, step_deg: float = 20.0) -> np.ndarray:
    """Integer label per unit normal: directions within about ``step_deg`` share a label."""
    theta = np.degrees(np.arccos(np.clip(normals[:, 2], -1.0, 1.0)))
    phi = np.degrees(np.arctan2(normals[:, 1], normals[:, 0])) % 360.0
    ring = np.floor(theta / step_deg).astype(np.int64)
    per_ring = np.maximum(1, np.round(360.0 * np.sin(np.radians((ring + 0.5) * step_deg)) / step_deg)).astype(np.int64)
    sector = np.floor(phi / 360.0 * per_ring).astype(np.int64) % per_ring
    return ring * 1000 + sector


def _fine_cells(mesh: Mesh, sel: np.ndarray, max_edge: float, max_area: float, max_cells: int):
    """Split the selected faces by longest-edge bisection into small triangles.

    A triangle is halved (its longest edge cut at the midpoint) until its
    longest edge is at most ``max_edge`` and its area at most ``max_area``
    (or the ``max_cells`` budget is reached). Slivers thus become a row of
    pieces along their length rather than k^2 congruent slivers.

    Returns centroids (K, 3), exact areas (K,), face index (K,).
    """
    tri = mesh.triangles[sel]
    face = np.flatnonzero(sel)
    done_t, done_f = [], []
    n_done = 0
    while len(tri):
        edges = np.roll(tri, -1, axis=1) - tri  # edge i from vertex i to i+1
        length = np.linalg.norm(edges, axis=2)
        area = 0.5 * np.linalg.norm(np.cross(edges[:, 0], -edges[:, 2]), axis=1)
        split = (length.max(axis=1) > max_edge) | (area > max_area)
        if n_done + len(tri) + int(split.sum()) > max_cells:
            split[:] = False
        done_t.append(tri[~split])
        done_f.append(face[~split])
        n_done += int((~split).sum())
        tri, face, length = tri[split], face[split], length[split]
        if not len(tri):
            break
        i = np.argmax(length, axis=1)  # cut edge i (vertices i, i+1) at its midpoint
        rows = np.arange(len(tri))
        a, b, c = tri[rows, i], tri[rows, (i + 1) % 3], tri[rows, (i + 2) % 3]
        mid = 0.5 * (a + b)
        tri = np.concatenate([np.stack([a, mid, c], 1), np.stack([mid, b, c], 1)])
        face = np.concatenate([face, face])
    tri, face = np.concatenate(done_t), np.concatenate(done_f)
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    return tri.mean(axis=1), area, face


def surface_quadrature(mesh: Mesh, n: int, *, face_mask: np.ndarray | None = None, seed: int = 0,
                       oversample: int = 16, iterations: int = 8, max_cells: int = 400_000) -> SurfaceSamples:
    """About ``n`` spatially compact, area-weighted quadrature points on a mesh surface.

    Parameters
    ----------
    mesh : Mesh
    n : int
        Number of points (>= 0); exactly ``n`` unless a normal group needs one more.
    face_mask : array_like of bool, shape (F,), optional
        Only these faces.
    seed : int
        Unused by the deterministic construction; kept so callers can vary
        sampling-based variants without changing signatures.
    oversample : int
        Fine sub-triangles per quadrature point (about).
    iterations : int
        Lloyd iterations refining the clusters.
    max_cells : int
        Cap on the number of fine sub-triangles (work bound).

    Returns
    -------
    SurfaceSamples
        Points whose areas sum exactly to the selected area.

    Notes
    -----
    The faces are split by longest-edge bisection into triangles with edges
    at most ``h / 2`` (``h = sqrt(A / n)``) and about ``oversample`` per
    point, whose areas are exact.
    They are grouped by normal direction (about 20 degree bins, so a point
    never averages the front and the side of an object); each group gets
    points in proportion to its area, starts as runs of equal area along a
    Morton curve, and is made compact by area-weighted Lloyd (k-means)
    iterations. A point is the sub-triangle centroid nearest its cluster's
    centroid (so it lies on the surface), carrying the cluster's exact area
    and mean normal. Clusters are compact whatever the triangulation (the
    sliver faces of a fan-triangulated disc included), so this is a midpoint
    rule on cells of size ``h``: error ``O(h^2) = O(1/n)`` for smooth
    integrands, against ``O(n^-1/2)`` for random samples.
    """
    del seed
    if not isinstance(mesh, Mesh):
        raise UserError(f"surface_quadrature needs a Mesh, got {type(mesh).__name__}")
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or int(n) < 0:
        raise UserError(f"number of quadrature points n={n!r} must be an integer >= 0")
    n = int(n)
    sel = mesh.face_areas > 0
    if face_mask is not None:
        sel &= np.asarray(face_mask, dtype=bool)
    key = (mesh.content_key, n, sel.tobytes(), int(oversample), int(iterations), int(max_cells))
    if key not in _QUADRATURES:  # deterministic: every plan of a mesh (layouts, worlds, batches) reuses it
        if len(_QUADRATURES) >= _QUADRATURE_CACHE_SIZE:
            _QUADRATURES.pop(next(iter(_QUADRATURES)))
        path = _quadrature_file(key)
        got = _load_quadrature(path)
        if got is None:
            got = _quadrature(mesh, n, sel, oversample, iterations, max_cells)
            _save_quadrature(path, got)
        _QUADRATURES[key] = got
    return _QUADRATURES[key]


#: Version of :func:`_quadrature`'s construction: part of the disk cache's key, raised when the points change.
QUADRATURE_VERSION = 1


def _quadrature_file(key: tuple) -> Path:
    """``$NLOSPLAN_CACHE/quadrature/DIGEST.npz``: a quadrature by its mesh's content, faces, point count and knobs."""
    from nlosplan.resources import cache_root

    digest = hashlib.sha1(repr((QUADRATURE_VERSION,) + key).encode()).hexdigest()
    return cache_root() / "quadrature" / f"{digest}.npz"


def _load_quadrature(path: Path) -> SurfaceSamples | None:
    """A cached quadrature, or None when there is none or it cannot be read (it is then computed again)."""
    try:
        with np.load(path, allow_pickle=False) as z:
            out = [np.array(z[k]) for k in ("points", "normals", "areas", "face_index")]
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        return None
    if not (out[0].ndim == 2 and out[0].shape[1:] == (3,) and out[1].shape == out[0].shape
            and out[2].shape == out[3].shape == out[0].shape[:1]):
        return None
    for a in out:
        a.setflags(write=False)
    return SurfaceSamples(points=out[0], normals=out[1], areas=out[2], face_index=out[3])


def _save_quadrature(path: Path, q: SurfaceSamples) -> None:
    """Write a quadrature for the next process (design workers, later runs): renamed into place whole.

    A cache: a folder that cannot be written only costs the next process the same 0.01-0.3 s per mesh
    again, so a failed write is dropped (the result in hand is right either way). No fsync: a torn file after a crash
    fails :func:`_load_quadrature`'s checks and is computed again.
    """
    with contextlib.suppress(OSError):  # a folder or disk that refuses the file: the result in hand stands
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=".tmp.npz", dir=path.parent)
        try:
            with os.fdopen(fd, "wb") as fh:
                np.savez(fh, points=q.points, normals=q.normals, areas=q.areas, face_index=q.face_index)
            os.replace(tmp, path)
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
            raise


#: Surface quadratures computed in this process, by mesh content, point count, faces and knobs (oldest dropped).
_QUADRATURES: dict = {}
_QUADRATURE_CACHE_SIZE = 1024


def _quadrature(mesh: Mesh, n: int, sel: np.ndarray, oversample: int, iterations: int,
                max_cells: int) -> SurfaceSamples:
    """:func:`surface_quadrature` on the faces ``sel`` (its arrays read-only: the result is shared)."""
    total = float(mesh.face_areas[sel].sum())
    if n == 0 or total <= 0:
        return _empty()
    h = np.sqrt(total / n)  # cluster size
    cen, area, face = _fine_cells(mesh, sel, 0.5 * h, total / n / oversample, max_cells)
    labels = _normal_bins(mesh.face_normals[face])
    groups = [np.flatnonzero(labels == g) for g in np.unique(labels)]
    share = np.array([area[g].sum() for g in groups]) / total * n
    counts = np.maximum(1, np.floor(share)).astype(np.int64)
    for i in np.argsort(-(share - np.floor(share))):  # largest remainders get the leftover points
        if counts.sum() >= n:
            break
        counts[i] += 1
    pts, nrm, wts, idx = [], [], [], []
    for g, c in zip(groups, counts):
        for run in _lloyd(cen[g], area[g], int(min(c, len(g))), iterations):
            run = g[run]
            w = area[run]
            p = (cen[run] * w[:, None]).sum(axis=0) / w.sum()
            nearest = run[np.argmin(np.linalg.norm(cen[run] - p, axis=1))]  # stay on the surface
            nr = (mesh.face_normals[face[run]] * w[:, None]).sum(axis=0)
            pts.append(cen[nearest])
            nrm.append(nr / np.linalg.norm(nr))
            wts.append(w.sum())
            idx.append(face[nearest])
    out = [np.array(pts), np.array(nrm), np.array(wts), np.array(idx, dtype=np.int64)]
    for a in out:
        a.setflags(write=False)
    return SurfaceSamples(points=out[0], normals=out[1], areas=out[2], face_index=out[3])


def _lloyd(points: np.ndarray, weights: np.ndarray, k: int, iterations: int) -> list[np.ndarray]:
    """Split weighted points into ``k`` compact clusters.

    Runs of equal weight along a Morton curve, refined by weighted Lloyd
    iterations. Returns the member indices of each non-empty cluster.
    """
    from scipy.spatial import cKDTree

    order = _morton_order(points)
    cum = np.cumsum(weights[order])
    label = np.empty(len(points), np.int64)
    label[order] = np.minimum((cum - 0.5 * weights[order]) / cum[-1] * k, k - 1).astype(np.int64)
    for _ in range(iterations):
        w = np.bincount(label, weights, minlength=k)
        live = w > 0
        centers = np.stack([np.bincount(label, weights * points[:, a], minlength=k) for a in range(3)], axis=1)
        centers = centers[live] / w[live, None]
        label = cKDTree(centers).query(points)[1]
        k = len(centers)
    order = np.argsort(label, kind="stable")
    bounds = np.flatnonzero(np.diff(label[order])) + 1
    return [m for m in np.split(order, bounds) if len(m)]
