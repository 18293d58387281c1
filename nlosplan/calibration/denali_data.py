"""DENALI-layout captures and the arrivals of their matching simulated scenes: the inputs of :mod:`.denali`.

Inputs are real (or simulated) histograms in DENALI's folder layout
(``<object>_<4inch|8inch>_<3x3|8x8>_<lighton|lightoff>_NLOSdata/spad_histogram/NNN.npy``,
``NNN`` the gantry position, shape ``(repeats, H, W, 128)``; parsed by
:func:`~nlosplan.data.denali_io.import_denali` into a temporary capture
store) or a :class:`~nlosplan.data.store.CaptureStore` file with an
optional label filter (:func:`load_denali_captures`). Every repeat is one
capture of the fit.

The matching simulated scene of a capture is
:func:`~nlosplan.simulators.presets.denali.denali_scene` of its object,
size and position; ``NOOBJECT`` is the rig without objects and
``NOOBJECTMOUNT`` the bare object mount (:func:`matching_scene`). That
reading is kept on purpose: DENALI's name for the post ("object mount")
suggests the other one (``NOOBJECTMOUNT`` = no mount), but the only data we
have, Table 2, prefer a ``NOOBJECT`` background without the mount (the
``calibrate --stats`` variants: objective 35.6 with the mount in the signal
vs 37.8 with it in the background; weak evidence). One real
``NOOBJECT - NOOBJECTMOUNT`` difference would decide it (docs/calibration.md).
Its arrivals per zone (:func:`scene_arrivals`) are

- the first-bounce returns of every zone sub-ray off the relay wall and the
  tables (:func:`~nlosplan.simulators.direct_arrivals`):
  ``t = path / c``, weight ``I s dOmega (albedo / pi) cos / r^2``;
- the object's three-bounce light: the ``object`` part of the fast
  simulator's expected counts for an ideal copy of the sensor (no impulse
  response, photon scale 1, one iteration, :data:`TRANSIENT_BIN_PS` bins from
  time 0), taken as arrivals at the bin centres. Fine bins below
  :data:`TRANSIENT_RTOL` of the zone's light are dropped.

Both are photons per iteration per unit photon scale, as the plane path's
(:func:`~nlosplan.simulators.wall_arrivals`), so ``photon_scale`` means the
same in both; it is relative to the scene's assumed albedos (relay wall
0.8, tables 0.5 by default: a wall of another albedo scales it).
The three-bounce light is ~1e-3 of the wall return: the time base, pulse and
scale are set by the wall; the object only keeps the model honest where it
shows. :func:`denali_capture_set` pairs the captures with these arrivals.
"""

from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from nlosplan.calibration.model import CaptureSet
from nlosplan.constants import C_M_PER_PS
from nlosplan.data.denali_io import NoCaptureFiles, import_denali
from nlosplan.data.records import describe
from nlosplan.data.store import CaptureStore
from nlosplan.denali import DENALI_OBJECTS
from nlosplan.errors import UserError
from nlosplan.sensor_models.config import MAX_BINS, SensorConfig
from nlosplan.simulators import direct_arrivals, expected_batch, resolve_fidelity
from nlosplan.simulators.presets.denali import denali_scene

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["TRANSIENT_BIN_PS", "TRANSIENT_RTOL", "DenaliCaptures", "check_sensor", "denali_capture_set",
           "is_capture_store", "load_denali_captures", "matching_scene", "scene_arrivals", "wall_zones"]

#: Width of the fine bins the three-bounce transient is taken on, ps (arrivals at their centres).
TRANSIENT_BIN_PS = 10.0
#: Three-bounce fine bins below this fraction of the zone's light are dropped (in all < 4.1e-4 of it).
TRANSIENT_RTOL = 1e-7
_SQLITE_MAGIC = b"SQLite format 3\x00"
_STORE_SUFFIXES = (".sqlite", ".sqlite3", ".db")


# --------------------------------------------------------------------- input
@dataclass(frozen=True, eq=False)
class DenaliCaptures:
    """DENALI captures, one row per repeat.

    Attributes
    ----------
    counts : ndarray, shape (N, Z, B)
        Counts (float64) of N captures, zones row-major.
    labels : pandas.DataFrame
        N rows: ``object`` (``NOOBJECT``, ``NOOBJECTMOUNT`` for the backgrounds),
        ``size``, ``position`` (gantry index 0..99), ``lights``, ``zones``,
        ``repeat``, ``source``, ``sensor_hash`` and the other store labels.
    sensor : SensorConfig or None
        The sensor the captures were stored with (None when they mix sensors).
    origin : str
        The folder or store they came from.
    """

    counts: np.ndarray
    labels: pd.DataFrame
    sensor: SensorConfig | None
    origin: str

    def __len__(self) -> int:
        return int(self.counts.shape[0])

    @property
    def zones(self) -> str:
        """The zone mode, e.g. ``"3x3"``."""
        return str(self.labels["zones"].iloc[0])

    @property
    def positions(self) -> np.ndarray:
        """Gantry position of each capture, shape (N,)."""
        return self.labels["position"].to_numpy(dtype=int)

    def scene_keys(self) -> list[tuple[str, str, int]]:
        """``(object, size, position)`` of each capture: what its simulated scene depends on."""
        lab = self.labels
        return [(str(o), str(s), int(p)) for o, s, p in zip(lab["object"], lab["size"], lab["position"])]

    def capture_labels(self) -> tuple[str, ...]:
        """One label per capture, e.g. ``"A_8in p19 off r0"``."""
        lab = self.labels
        return tuple(f"{o}_{s} p{int(p):02d} {li} r{int(r)}" for o, s, p, li, r in
                     zip(lab["object"], lab["size"], lab["position"], lab["lights"], lab["repeat"]))

    def floor_groups(self) -> list[str]:
        """Captures that share a floor: one DENALI folder (object, size, lights) each, e.g. ``"A_8in off"``."""
        lab = self.labels
        return [f"{o}_{s} {li}" for o, s, li in zip(lab["object"], lab["size"], lab["lights"])]

    def describe(self) -> dict:
        """JSON-ready summary: origin, captures, positions, scenes, zones, lights, sources."""
        lab = self.labels
        return {"origin": self.origin, "captures": len(self), "positions": int(lab["position"].nunique()),
                "objects": sorted({f"{o}_{s}" for o, s in zip(lab["object"], lab["size"])}),
                "zones": self.zones, "lights": sorted(lab["lights"].astype(str).unique()),
                "sources": sorted(lab["source"].astype(str).unique())}


def is_capture_store(path) -> bool:
    """Whether ``path`` names a capture store: an SQLite file, or a missing file ending in .sqlite/.sqlite3/.db."""
    path = Path(path)
    if path.is_file():
        try:
            with open(path, "rb") as f:
                return f.read(len(_SQLITE_MAGIC)) == _SQLITE_MAGIC
        except OSError:
            return False
    return not path.exists() and path.suffix.lower() in _STORE_SUFFIXES


def load_denali_captures(path, where: dict | None = None, *, positions_json=None,
                         trust_pickle: bool = False) -> DenaliCaptures:
    """DENALI captures from a DENALI-layout folder or a capture store.

    Parameters
    ----------
    path : str or Path
        A folder holding ``*_NLOSdata`` folders (read through
        :func:`~nlosplan.data.denali_io.import_denali` into a temporary store),
        or a capture store file (``nlosplan dataset import-denali`` or ``dataset build``).
    where : dict, optional
        Label filter as :meth:`~nlosplan.data.store.CaptureStore.load` takes it
        (``{"lights": "off", "object": ["A", "NOOBJECT"]}``). Means over repeats
        (``repeat < 0``) are always left out: they are not Poisson counts.
    positions_json : str or Path, optional
        Folder input: ``tag1_positions.json`` (default: the packaged DENALI one).
    trust_pickle : bool
        Folder input: allow capture files that need pickle.

    Returns
    -------
    DenaliCaptures

    Raises
    ------
    UserError
        Not a DENALI-layout folder nor a store; nothing matches; the captures
        mix zone modes (or bin widths).
    """
    path = Path(path)
    if path.is_dir():
        if path.name.endswith("_NLOSdata"):
            raise UserError(f"{path} is not a DENALI-layout folder: no <object>_<4inch|8inch>_<RxC>_<lighton|lightoff>"
                            f"_NLOSdata/spad_histogram/NNN.npy in it (give the folder that holds {path.name}, not "
                            "the capture folder itself)")
        with tempfile.TemporaryDirectory(prefix="nlosplan-calibrate-") as tmp:
            with CaptureStore(Path(tmp) / "captures.sqlite", synchronous="NORMAL") as st:
                try:
                    import_denali(path, st, positions_json=positions_json, trust_pickle=trust_pickle)
                except NoCaptureFiles as exc:
                    raise UserError(f"{path} is not a DENALI-layout folder: {exc}") from None
                return _from_store(st, where, str(path))
    if path.exists() and not is_capture_store(path):
        raise UserError(f"{path} is neither a DENALI-layout folder nor a capture store (.sqlite)")
    with CaptureStore(path, readonly=True) as st:
        return _from_store(st, where, str(path))


def _from_store(st, where: dict | None, origin: str) -> DenaliCaptures:
    where = dict(where or {})
    labels = st.labels(**where)
    labels = labels[labels["repeat"] >= 0]
    if labels.empty:
        raise UserError(f"no captures in {origin} match {describe(where)}")
    modes = sorted(labels["zones"].astype(str).unique())
    if len(modes) > 1:
        raise UserError(f"the captures in {origin} mix zone modes {', '.join(modes)}; calibrate one at a time, "
                        f"e.g. --where zones={modes[0]}")
    ds = st.load(**where)
    keep = (ds.labels["repeat"] >= 0).to_numpy()
    counts = np.asarray(ds.histograms[keep], dtype=np.float64)
    lab = ds.labels[keep].reset_index(drop=True)
    hashes = lab["sensor_hash"].unique()
    sensor = st.sensor(str(hashes[0])) if len(hashes) == 1 else None
    return DenaliCaptures(counts.reshape(counts.shape[0], -1, counts.shape[-1]), lab, sensor, origin)


# --------------------------------------------------------------------- matching scenes and their arrivals
def matching_scene(obj: str, size: str, position: int, lights="off", **options):
    """The simulated scene of one DENALI capture.

    Parameters
    ----------
    obj : str
        A DENALI object, ``"NOOBJECT"`` (the rig alone) or ``"NOOBJECTMOUNT"`` (the bare mount).
    size, position, lights
        As :func:`~nlosplan.simulators.presets.denali.denali_scene`.
    **options
        Further ``denali_scene`` keywords (albedos, reflectance, ``mount``, ``tables``).

    Returns
    -------
    Scene
    """
    if obj == "NOOBJECT":
        return denali_scene(DENALI_OBJECTS[0], size, position, lights, **options).without_objects()
    if obj == "NOOBJECTMOUNT":  # the preset's mount (pose and albedo), without the object it holds
        full = denali_scene(DENALI_OBJECTS[0], size, position, lights, **{**options, "mount": True})
        return full.replace(objects=full.objects[1:], meta={**full.meta, "object": obj})
    return denali_scene(obj, size, position, lights, **options)


def _latest_arrival_ps(scenes) -> float:
    """Bound on every three-bounce arrival time of the scenes, ps (as the fast plan bounds its grid)."""
    wall = scenes[0].wall.corners()
    r_wall = float(np.linalg.norm(wall - scenes[0].lidar.position, axis=1).max())
    d = max(float(np.linalg.norm(wall[:, None] - o.world_vertices()[None], axis=-1).max())
            for sc in scenes for o in sc.objects)
    return 2.0 * (r_wall + d) / C_M_PER_PS


def _ideal_sensor(sensor: SensorConfig, t_max_ps: float) -> SensorConfig:
    """``sensor``'s zones, field of view and flash with an ideal time axis from 0 to ``t_max_ps``."""
    width = max(TRANSIENT_BIN_PS, t_max_ps / MAX_BINS)
    return sensor.replace(name=f"{sensor.name} (ideal transient)", n_bins=int(min(math.ceil(t_max_ps / width) + 1,
                                                                                   MAX_BINS)),
                          bin_width_ps=width, start_offset_ps=0.0, pulse_shape=None, pulse_fwhm_ps=0.0,
                          jitter_fwhm_ps=0.0, photon_scale=1.0, iterations=1, ambient_rate_hz=0.0, dark_rate_hz=0.0,
                          crosstalk=0.0, pileup=False, saturation=False)


def scene_arrivals(keys, sensor: SensorConfig, *, fidelity="default",
                   scene_options: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Arrival times and weights of the matching simulated scenes, per zone.

    Parameters
    ----------
    keys : sequence of (str, str, int)
        ``(object, size, position)`` of each scene (see :meth:`DenaliCaptures.scene_keys`).
    sensor : SensorConfig
        Zones, field of view, flash profile and zone sensitivity are used; the
        time axis, pulse and photon scale are not.
    fidelity : str, dict or Fidelity
        Fast-simulator quadrature: ``zone_sub`` sub-rays per zone axis for the
        first bounce, the object quadrature for the three bounces.
    scene_options : dict, optional
        Further :func:`~nlosplan.simulators.presets.denali.denali_scene` keywords.

    Returns
    -------
    times_ps : ndarray, shape (M, Z, K)
        Arrival times of the M scenes, ps: ``S = zone_sub**2`` first-bounce
        sub-rays, then the three-bounce fine-bin centres (padded).
    weights : ndarray, shape (M, Z, K)
        Photons per iteration per unit photon scale (0 for padding and misses).

    Notes
    -----
    Matches the fast simulator: with these arrivals,
    :func:`~nlosplan.calibration.model.make_model` at a
    sensor's parameters gives its expected counts
    (``expected_histogram(scene, sensor)``) to well under 1 % where
    the wall return shows.
    """
    keys = [(str(o), str(s), int(p)) for o, s, p in keys]
    if not keys:
        raise UserError("no scenes to simulate")
    fid = resolve_fidelity(fidelity)
    opts = dict(scene_options or {})
    rig = matching_scene(*keys[0], **opts)
    t_direct, w_direct, _ = direct_arrivals(rig, sensor, fidelity=fid)  # (Z, S)
    n_zones = sensor.n_zones
    groups: dict[str, list[int]] = {}  # one simulator per object model (meshes may differ inside a batch)
    for m, (o, _, _) in enumerate(keys):
        if o != "NOOBJECT":
            groups.setdefault("mount" if o == "NOOBJECTMOUNT" else "object", []).append(m)
    obj_t: list = [[np.zeros(0)] * n_zones for _ in keys]
    obj_w: list = [[np.zeros(0)] * n_zones for _ in keys]
    for members in groups.values():
        scenes = [matching_scene(*keys[m], **opts) for m in members]
        ideal = _ideal_sensor(sensor, _latest_arrival_ps(scenes))
        light = expected_batch(scenes, ideal, fidelity=fid, parts=True).parts["object"]
        light = np.asarray(light, dtype=np.float64).reshape(len(scenes), n_zones, -1)
        centres = (np.arange(light.shape[-1]) + 0.5) * ideal.bin_width_ps
        for j, m in enumerate(members):
            for z in range(n_zones):
                total = w_direct[z].sum() + light[j, z].sum()
                keep = light[j, z] > TRANSIENT_RTOL * total
                obj_t[m][z], obj_w[m][z] = centres[keep], light[j, z, keep]
    k_obj = max((v.size for row in obj_w for v in row), default=0)
    s = t_direct.shape[1]
    times = np.zeros((len(keys), n_zones, s + k_obj))
    weights = np.zeros_like(times)
    times[:, :, :s], weights[:, :, :s] = t_direct, w_direct
    for m in range(len(keys)):
        for z in range(n_zones):
            n = obj_w[m][z].size
            times[m, z, s: s + n], weights[m, z, s: s + n] = obj_t[m][z], obj_w[m][z]
    return times, weights


def wall_zones(sensor: SensorConfig, *, fidelity="default", scene_options: dict | None = None) -> list[int]:
    """Flat indices of the zones that see the relay wall (some sub-ray's first hit is on it)."""
    rig = matching_scene("NOOBJECT", "8in", 0, **dict(scene_options or {}))
    _, w, plane = direct_arrivals(rig, sensor, fidelity=fidelity)
    return [int(z) for z in np.flatnonzero(np.any((plane == 0) & (w > 0), axis=1))]


def check_sensor(captures: DenaliCaptures, sensor: SensorConfig) -> None:
    """Raise :class:`UserError` unless ``sensor`` has the captures' zones and bins."""
    z, b = captures.counts.shape[1:]
    if sensor.n_zones != z or f"{sensor.zones_rows}x{sensor.zones_cols}" != captures.zones:
        raise UserError(f"the captures have {captures.zones} zones but sensor {sensor.name} has "
                        f"{sensor.zones_rows}x{sensor.zones_cols}; give a matching --sensor")
    if sensor.n_bins != b:
        raise UserError(f"the captures have {b} bins but sensor {sensor.name} has {sensor.n_bins}; "
                        "give a matching --sensor")


def denali_capture_set(captures: DenaliCaptures, sensor: SensorConfig, *, zones=None, fidelity="default",
                       scene_options: dict | None = None) -> CaptureSet:
    """The captures with the arrivals of their matching simulated scenes.

    Parameters
    ----------
    captures : DenaliCaptures
    sensor : SensorConfig
        The sensor to calibrate: its zones and bins must be the captures';
        its ``iterations`` are the captures'.
    zones : list of int, optional
        Flat zone indices to keep (default: :func:`wall_zones`).
    fidelity, scene_options
        As :func:`scene_arrivals`.

    Returns
    -------
    CaptureSet
        counts (N, Z, B), times_ps and weights (N, Z, K), one capture per repeat.
    """
    check_sensor(captures, sensor)
    zones = wall_zones(sensor, fidelity=fidelity, scene_options=scene_options) if zones is None else list(zones)
    if not zones or any(not 0 <= z < sensor.n_zones for z in zones):
        raise UserError(f"zones {zones} must be flat zone indices 0..{sensor.n_zones - 1}")
    keys = captures.scene_keys()
    unique = list(dict.fromkeys(keys))
    t, w = scene_arrivals(unique, sensor, fidelity=fidelity, scene_options=scene_options)
    where = {u: i for i, u in enumerate(unique)}
    idx = np.array([where[k] for k in keys])
    return CaptureSet(captures.counts[:, zones], t[idx][:, zones], w[idx][:, zones], int(sensor.iterations),
                      captures.capture_labels())
