"""What the design evaluators read: reference histograms per zone layout, and their degradation to a design.

Every design is *emulated* from a reference: the best sensor of the space for
each zone layout (simulated once with the fast backend), or real captures (a
capture store or DENALI folder), degraded by
:mod:`nlosplan.sensor_models.degrade`. A design finer than the reference is
unreachable and reported so, never extrapolated.

The reference data is saved to one ``.npz`` file per layout so that worker
processes (local pool or Dask) load it once and a resumed run does not
simulate again.
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from nlosplan.errors import UserError
from nlosplan.files import atomic_path
from nlosplan.sensor_models import SensorConfig
from nlosplan.sensor_models.degrade import Degradation, degrade_counts, degrade_expected, degrade_linear, reach
from nlosplan.sensor_models.noise import CaptureNoise

__all__ = ["SceneSet", "ReferenceData", "simulate_reference", "reference_from_dataset", "load_reference",
           "build_reference"]

#: Label columns a reference keeps (a subset of the data room's LABEL_COLUMNS).
REFERENCE_COLUMNS = ("object", "size", "class_group", "position", "x", "y", "lights")


@dataclass(frozen=True)
class SceneSet:
    """Which simulated DENALI scenes the evaluators use.

    Parameters
    ----------
    objects : tuple of str
        DENALI objects (the shape task's classes).
    sizes : tuple of str
    positions : tuple of int
        Gantry positions (0-99).
    lights : str
    repeats : int
        Noisy captures per scene for the trained evaluator (averaged, as DENALI does).
    crlb_objects : tuple of str
        Objects of the localization bound's scenes (all sizes, every ``crlb_stride``-th position);
        none: no bound scenes (a world's reference).
    crlb_stride : int
    fidelity : str
        Simulator level of the reference histograms.
    backend : str
        Simulator of the reference histograms, from :data:`nlosplan.simulators.BACKENDS`: the fast JAX backend, or
        the Mitsuba 3 twin (about
        0.1 s per scene and zone layout on 2 cores; it measures the relay wall only). The bound
        scenes' Jacobians always come from the fast backend (the twin is not differentiated here).
    scene_kwargs : tuple of (str, float or bool)
        Keyword arguments of every :func:`~nlosplan.simulators.denali_scene` (a world's scene overrides,
        e.g. ``(("albedo", 0.4),)``); they replace the scene model's.
    model : str
        The calibrated scene model the reference sensor comes with
        (:func:`~nlosplan.simulators.presets.scene_model.scene_model`: ``"denali-tmf8828-3x3"`` — the
        Table-2 fit's albedo, diffuse base and mount in the signal), or ``""`` for the scene's defaults.
        :class:`~nlosplan.planner.design.run.DesignConfig` sets it from the space's reference.
    session_floor_sd : float or None
        How far one capture session's floor moves (standard deviation, a fraction of the floor; a session is one
        object, size and lighting, as DENALI records them): None takes the scene model's
        (:func:`~nlosplan.simulators.presets.scene_model.session_floor_sd`: 1.73 % for DENALI's unit, 0 without a
        model); 0 gives every session the sensor's floor (the ablation).
    """

    objects: tuple[str, ...]
    sizes: tuple[str, ...] = ("4in", "8in")
    positions: tuple[int, ...] = tuple(range(0, 100, 2))
    lights: str = "off"
    repeats: int = 2
    crlb_objects: tuple[str, ...] = ("A", "S", "circle")
    crlb_stride: int = 5
    fidelity: str = "low"
    backend: str = "fast"
    scene_kwargs: tuple = ()
    model: str = ""
    session_floor_sd: float | None = None

    def __post_init__(self) -> None:
        from nlosplan.data.build import MAX_SESSION_FLOOR_SD
        from nlosplan.simulators import check_backend

        check_backend(self.backend)
        sd = self.session_floor_sd
        if sd is not None:
            if isinstance(sd, bool) or not isinstance(sd, (int, float)) or not 0 <= sd <= MAX_SESSION_FLOOR_SD:
                raise UserError(f"session_floor_sd={sd!r} must be a number from 0 to {MAX_SESSION_FLOOR_SD:g} (a "
                                "fraction of the floor)")
            object.__setattr__(self, "session_floor_sd", float(sd))
        kw = self.scene_kwargs.items() if isinstance(self.scene_kwargs, dict) else self.scene_kwargs
        object.__setattr__(self, "scene_kwargs", tuple(sorted(
            (str(k), bool(v) if isinstance(v, bool) else float(v)) for k, v in kw)))

    def options(self) -> dict:
        """The :func:`~nlosplan.simulators.denali_scene` keywords of every scene: the model's, then ``scene_kwargs``."""
        from nlosplan.simulators.presets.scene_model import scene_options

        return {**scene_options(self.model), **dict(self.scene_kwargs)}

    def session_sd(self) -> float:
        """The capture sessions' floor spread these scenes are drawn with (``session_floor_sd`` resolved)."""
        from nlosplan.simulators.presets.scene_model import session_floor_sd

        return session_floor_sd(self.model) if self.session_floor_sd is None else self.session_floor_sd

    def to_dict(self) -> dict:
        out = {k: list(v) if isinstance(v, tuple) else v for k, v in self.__dict__.items()}
        del out["session_floor_sd"]
        if self.session_sd():  # the spread's value (a scene set without sessions keeps the key it had)
            out["session_floor_sd"] = self.session_sd()
        if not self.scene_kwargs:  # the key of a run without worlds stays what it was
            del out["scene_kwargs"]
        else:
            out["scene_kwargs"] = [list(kv) for kv in self.scene_kwargs]
        if not self.model:  # nor that of a sensor without a calibrated scene model
            del out["model"]
        else:
            out["scene_options"] = self.options()  # the values, so a refit of the model changes the key
        return out

    @classmethod
    def from_dict(cls, data: dict) -> "SceneSet":
        """From :meth:`to_dict` (lists as tuples; ``scene_options`` is derived, not read)."""
        kw = {k: tuple(tuple(x) if isinstance(x, list) else x for x in v) if isinstance(v, list) else v
              for k, v in data.items() if k != "scene_options"}
        kw.setdefault("session_floor_sd", 0.0)   # to_dict leaves out a spread of 0
        return cls(**kw)

    @property
    def n_scenes(self) -> int:
        return len(self.objects) * len(self.sizes) * len(self.positions)

    def key(self, sensor: SensorConfig) -> str:
        text = json.dumps({"scenes": self.to_dict(), "sensor": sensor.to_dict()}, sort_keys=True, default=str)
        return hashlib.sha1(text.encode()).hexdigest()[:12]


@dataclass(frozen=True, eq=False)
class ReferenceData:
    """Reference histograms of one zone layout.

    Parameters
    ----------
    sensor : SensorConfig
        The reference sensor these histograms belong to.
    labels : pandas.DataFrame
        One row per scene (or capture): :data:`REFERENCE_COLUMNS`.
    means : ndarray, shape (N, R, C, B) or None
        Expected counts (simulated references).
    counts : ndarray, shape (N, R, C, B) or None
        Photon counts (real references; one row per capture).
    crlb_lam : ndarray, shape (M, R, C, B) or None
        Expected counts of the localization-bound scenes.
    crlb_jac : ndarray, shape (M, R, C, B, P) or None
        Their derivatives: x, y (per metre), then log photon scale.
    crlb_labels : pandas.DataFrame or None
        Labels of the M bound scenes.
    source : str
        ``"fast"`` or the path of the real captures.
    seconds : float
        Time to build it.
    session_floor_sd : float
        The capture sessions' floor spread (a fraction of the reference sensor's floor) that noisy captures drawn
        from ``means`` get (:meth:`session_offsets`); 0: one floor for every session. Real captures carry their
        own sessions.
    """

    sensor: SensorConfig
    labels: pd.DataFrame
    means: np.ndarray | None = None
    counts: np.ndarray | None = None
    crlb_lam: np.ndarray | None = None
    crlb_jac: np.ndarray | None = None
    crlb_labels: pd.DataFrame | None = None
    source: str = "fast"
    seconds: float = 0.0
    session_floor_sd: float = 0.0

    @property
    def zones(self) -> tuple[int, int]:
        return self.sensor.zones_rows, self.sensor.zones_cols

    @property
    def is_counts(self) -> bool:
        return self.means is None

    def degradation(self, design_sensor: SensorConfig) -> tuple[Degradation | None, str]:
        """How to reach ``design_sensor`` from this reference (None and the reason if it cannot)."""
        return reach(self.sensor, design_sensor, counts=self.is_counts)

    def design_means(self, d: Degradation, *, session_seed: int | None = None) -> np.ndarray:
        """Expected counts of the design, (N, R', C', B'); with ``session_seed``, each scene's floor moved by its
        capture session (:meth:`session_offsets`), as :meth:`design_mean_capture` draws the captures."""
        if self.means is None:
            raise UserError("real captures have no expected counts; the bounds use the simulated reference")
        return degrade_expected(self._session_means(slice(None), session_seed), d)

    def _session_means(self, idx, session_seed: int | None) -> np.ndarray:
        means = self.means[idx]   # a view of every scene without rows (no copy of an 8x8 reference)
        if session_seed is not None and self.session_floor_sd:
            shift = self.session_offsets(session_seed)[idx]
            means = np.maximum(means + shift[:, None, None, None], 0.0)
        return means

    def session_offsets(self, seed: int) -> np.ndarray:
        """How far each scene's capture session moves the floor, counts per bin of the reference sensor, (N,).

        A session is one object, size and lighting (every position and repeat of it recorded in one sitting, as
        DENALI records a folder): its floor is ``1 + shift`` times the reference sensor's, ``shift`` the dataset
        build's draw (:func:`~nlosplan.data.build.session_shift`) for ``seed`` and the session's labels, so every
        position of a session moves together and a run at another seed meets other sessions. Zeros when
        ``session_floor_sd`` is 0.
        """
        n = len(self.labels)
        if not self.session_floor_sd:
            return np.zeros(n)
        from nlosplan.data.build import session_shift
        from nlosplan.sensor_models.noise import floor_counts

        floor = {lights: floor_counts(self.sensor, lights == "on") for lights in ("on", "off")}
        shifts = {}
        out = np.empty(n)
        for i, (obj, size, lights) in enumerate(zip(self.labels["object"], self.labels["size"], self.labels["lights"])):
            key = (obj, size, lights)
            if key not in shifts:
                shifts[key] = session_shift(seed, obj, size, lights, self.session_floor_sd) * floor[lights]
            out[i] = shifts[key]
        return out

    def design_mean_capture(self, d: Degradation, rng, repeats: int, rows=None, *,
                            session_seed: int | None = None) -> np.ndarray:
        """The mean of ``repeats`` noisy captures of the design, (N, R', C', B') float64 (real: the capture rows).

        Simulated: the reference sensor's :meth:`~nlosplan.sensor_models.noise.CaptureNoise.mean_of_repeats` of the
        design's expected counts, each scene's floor moved by its capture session (:meth:`session_offsets` of
        ``session_seed``) before the design's degradation.

        Parameters
        ----------
        d : Degradation
        rng : numpy.random.Generator or seed
        repeats : int
            Captures averaged into one.
        rows : ndarray of int, shape (M,), optional
            Only these scenes (repeated indices draw a scene again, independently): (M, R', C', B'). Simulated
            references only: real captures cannot be drawn again.
        session_seed : int, optional
            Seed of the capture sessions' floors (the evaluation's seed); None: no session term.
        """
        rng = np.random.default_rng(rng)
        if self.means is None:
            if rows is not None:
                raise UserError("real captures cannot be drawn again: a capture is what was captured")
            return degrade_counts(self.counts, d, rng).astype(np.float64)
        idx = slice(None) if rows is None else np.asarray(rows, dtype=np.int64)
        means = self._session_means(idx, session_seed)
        return CaptureNoise.of(self.sensor).mean_of_repeats(rng, degrade_expected(means, d), repeats)

    def design_crlb(self, d: Degradation) -> tuple[np.ndarray, np.ndarray]:
        """``(lam, jac)`` of the localization-bound scenes under the design."""
        if self.crlb_lam is None:
            raise UserError("this reference has no localization-bound scenes")
        return degrade_expected(self.crlb_lam, d), degrade_linear(self.crlb_jac, d)

    # --------------------------------------------------------------- files
    def save(self, path: str | Path) -> Path:
        path = Path(path)
        arrays = {k: getattr(self, k) for k in ("means", "counts", "crlb_lam", "crlb_jac") if getattr(self, k) is not None}
        meta = {"sensor": self.sensor.to_dict(), "source": self.source, "seconds": self.seconds,
                "session_floor_sd": self.session_floor_sd,
                "labels": self.labels.to_dict(orient="list"),
                "crlb_labels": None if self.crlb_labels is None else self.crlb_labels.to_dict(orient="list")}
        with atomic_path(path) as tmp:
            np.savez(tmp, meta=np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8), **arrays)
        return path


_CACHE: dict[str, ReferenceData] = {}


def load_reference(path: str | Path) -> ReferenceData:
    """A saved :class:`ReferenceData` (cached per process: workers load each file once)."""
    key = str(Path(path).resolve())
    if key not in _CACHE:
        with np.load(key, allow_pickle=False) as z:
            meta = json.loads(bytes(z["meta"]).decode())
            arrays = {k: z[k] for k in ("means", "counts", "crlb_lam", "crlb_jac") if k in z}
        crlb_labels = None if meta.get("crlb_labels") is None else pd.DataFrame(meta["crlb_labels"])
        _CACHE[key] = ReferenceData(SensorConfig.from_dict(meta["sensor"]), pd.DataFrame(meta["labels"]),
                                    crlb_labels=crlb_labels, source=meta["source"], seconds=meta["seconds"],
                                    session_floor_sd=float(meta.get("session_floor_sd", 0.0)), **arrays)
    return _CACHE[key]


def _scene_labels(objects, sizes, positions, lights) -> pd.DataFrame:
    from nlosplan.denali import class_group, positions_xy

    xy = positions_xy()
    rows = [{"object": o, "size": s, "class_group": class_group(o), "position": p, "x": float(xy[p, 0]),
             "y": float(xy[p, 1]), "lights": lights} for o in objects for s in sizes for p in positions]
    return pd.DataFrame(rows, columns=list(REFERENCE_COLUMNS))


#: This process's last plan of a zone layout's nominal scenes (:func:`_nominal_plan`): its worlds' references pad to it.
_NOMINAL_PLAN: dict = {}


def _nominal_plan(sensor: SensorConfig, scenes: SceneSet, min_support_sigma_ps: float):
    """The fast simulator's plan of ``scenes`` (a layout's nominal references) under ``sensor``, kept for the next call.

    A world's references simulate every second position of the nominal scenes: their plan can come out with
    smaller near-wall blocks or time ranges than the nominal one, hence another compiled program. Padded to this
    plan, they run the program the references stage compiled. One plan is kept (a worker holds one layout).
    """
    from nlosplan.simulators import denali_scene, plan_batch

    key = (json.dumps(scenes.to_dict(), sort_keys=True), sensor.zones_rows, sensor.zones_cols,
           float(min_support_sigma_ps))
    if key not in _NOMINAL_PLAN:
        kw = scenes.options()
        batch = [denali_scene(obj, s, p, lights=scenes.lights, **kw)
                 for obj in scenes.objects for s in scenes.sizes for p in scenes.positions]
        _NOMINAL_PLAN.clear()
        _NOMINAL_PLAN[key] = plan_batch(batch, sensor, fidelity=scenes.fidelity,
                                        min_support_sigma_ps=min_support_sigma_ps)
    return _NOMINAL_PLAN[key]


def simulate_reference(sensor: SensorConfig, scenes: SceneSet, *, progress=None,
                       min_support_sigma_ps: float = 0.0, pad_scenes: SceneSet | None = None) -> ReferenceData:
    """Simulate the reference histograms of one zone layout (the scene set's backend; the bound scenes: fast).

    Parameters
    ----------
    sensor : SensorConfig
        The reference sensor of the layout (finest timing, all bins, the most photons of the space).
    scenes : SceneSet
    progress : callable, optional
        Called with a short text after each step.
    min_support_sigma_ps : float
        Fast backend: plan the impulse response for at least this Gaussian sigma, ps (references of sensors
        with different jitter then run one compiled program; equal within float32 rounding); 0 for the twin,
        which has no plan (:func:`~nlosplan.simulators.expected_batch` refuses anything else).
    pad_scenes : SceneSet, optional
        Fast backend: pad the plan to these scenes' (a superset: the layout's nominal references, of which a
        world's references take every second position), so both run one compiled program; equal within float32
        rounding.

    Returns
    -------
    ReferenceData
        ``means`` (N, R, C, B) for N = objects x sizes x positions and the
        localization-bound scenes' ``crlb_lam``, ``crlb_jac``.
    """
    from nlosplan.simulators import counts_and_jacobian, denali_scene, expected_batch

    t0 = time.perf_counter()
    labels = _scene_labels(scenes.objects, scenes.sizes, scenes.positions, scenes.lights)
    kw = scenes.options()
    # every object in one batch: the fast backend runs one plan and one compiled simulator for all of them (a batch
    # per object compiled again for each object's padding sizes), and a gantry mount the same under every object at
    # a position is simulated once per position, not once per object and size; the twin renders them in turn
    batch = [denali_scene(obj, s, p, lights=scenes.lights, **kw)
             for obj in scenes.objects for s in scenes.sizes for p in scenes.positions]
    step = None
    if progress:
        step = lambda done, total: progress(  # noqa: E731
            f"{sensor.zones_rows}x{sensor.zones_cols} {done}/{total} scenes")
    # the twin's "relay wall only" is said once in the report, not per scene: its warnings are not repeated here
    pad = None
    if pad_scenes is not None and scenes.backend == "fast":
        pad = _nominal_plan(sensor, pad_scenes, min_support_sigma_ps)  # not padded where the worlds' structure differs
    means = np.asarray(expected_batch(batch, sensor, backend=scenes.backend, fidelity=scenes.fidelity,
                                      progress=step, min_support_sigma_ps=min_support_sigma_ps,
                                      pad_to=pad).expected, np.float32)
    sd = scenes.session_sd()
    if not scenes.crlb_objects:
        return ReferenceData(sensor, labels, means=means, source=scenes.backend,
                             seconds=time.perf_counter() - t0, session_floor_sd=sd)
    crlb_pos = scenes.positions[:: scenes.crlb_stride]
    crlb_scenes = [denali_scene(o, s, p, lights=scenes.lights, **kw) for o in scenes.crlb_objects
                   for s in scenes.sizes for p in crlb_pos]
    lam, jac, _, _ = counts_and_jacobian(crlb_scenes, sensor, fidelity=scenes.fidelity)
    r, c = sensor.zones_rows, sensor.zones_cols
    lam = lam.reshape(len(crlb_scenes), r, c, -1)
    jac = jac.reshape(len(crlb_scenes), r, c, lam.shape[-1], -1)
    if progress:
        progress(f"{r}x{c} bound scenes")
    return ReferenceData(sensor, labels, means=means, crlb_lam=lam, crlb_jac=jac,
                         crlb_labels=_scene_labels(scenes.crlb_objects, scenes.sizes, crlb_pos, scenes.lights),
                         source=scenes.backend, seconds=time.perf_counter() - t0, session_floor_sd=sd)


def reference_from_dataset(dataset, sensor: SensorConfig, source: str) -> ReferenceData:
    """Real captures as a reference (counts; one row per capture, repeats kept).

    Parameters
    ----------
    dataset : nlosplan.data.dataset.Dataset
        Counts (N, R, C, B) with labels.
    sensor : SensorConfig
        The sensor that captured them (its zones and bins must match the histograms).
    source : str
        Where they come from (for the report).
    """
    h = np.asarray(dataset.histograms)
    if h.shape[1:] != (sensor.zones_rows, sensor.zones_cols, sensor.n_bins):
        raise UserError(f"captures are {h.shape[1]}x{h.shape[2]} zones x {h.shape[3]} bins but the capture sensor "
                        f"{sensor.name} is {sensor.zones_rows}x{sensor.zones_cols} x {sensor.n_bins}; "
                        "give the matching --capture-sensor")
    if np.any(h < 0) or not np.allclose(h, np.round(h)):
        raise UserError("real captures must be photon counts (non-negative integers)")
    labels = dataset.labels.reset_index(drop=True)
    missing = [c for c in REFERENCE_COLUMNS if c not in labels.columns]
    if missing:
        raise UserError(f"captures lack label column(s) {', '.join(missing)}")
    return ReferenceData(sensor, labels[list(REFERENCE_COLUMNS)].copy(), counts=np.round(h).astype(np.int64),
                         source=source)


def build_reference(job) -> dict:
    """Simulate and save one reference unless its file exists (runs on any executor).

    Parameters
    ----------
    job : ReferenceJob
        ``path``, ``sensor`` and ``scenes`` (:class:`~nlosplan.planner.design.jobs.ReferenceJob`).

    Returns
    -------
    dict
        ``path``, ``status`` (``"ok"``), ``seconds`` (simulation time; 0 when the file was there) and
        ``scenes``.
    """
    path = Path(job.path)
    seconds = 0.0
    if not path.exists():
        ref = simulate_reference(job.sensor, job.scenes, min_support_sigma_ps=job.min_support_sigma_ps,
                                 pad_scenes=job.pad_scenes)
        ref.save(path)
        seconds = ref.seconds
    return {"path": str(path), "status": "ok", "seconds": seconds, "scenes": job.scenes.n_scenes,
            "label": job.label}
