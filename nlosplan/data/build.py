"""Simulated DENALI datasets: batches of scenes through the fast simulator, Poisson captures, into a store.

The positions are cut into runs of ``batch``; for each run, every requested
object, size and lighting (as many as :data:`SCENES_PER_SIMULATION` allows)
is simulated in ONE call of the fast backend's batch seam
(:func:`~nlosplan.simulators.expected_batch`): an object's light is the same
under both lightings and the gantry's mount the same under every object at a
position, so the simulator computes each once (its shared terms), and each
simulation is padded to the previous one's plan (``pad_to``), so the build
compiles one program. Each scene then gets ``repeats`` Poisson captures drawn
with its own seed, derived from ``(seed, object, size, position, lights)``
alone. Every capture is committed on its own
(:meth:`~nlosplan.data.store.CaptureStore.put_many`), so an interrupted build
keeps what it stored, and a rerun with the same arguments skips what is
stored and gives the same counts.

Speed (issue 38, default model ``denali-tmf8828-3x3``: mixed reflectance and
the mount; ``--objects A,S,O,plus,7 --lights on,off --repeats 3``, 6,000
captures, cold, a 2-core VM shared with other jobs at load 8-9): 94 s, 64
captures/s, against the one-group-at-a-time build of before in the same
session (see ``docs/tasks.md`` for the ratio). DENALI's full set (all 30
objects, ``--lights on,off --repeats 3``: 36,000 captures) on one core
pinned while other jobs ran on the other, a fresh store: 93 s (387
captures/s) against 112-128 s before issue 38's fourth pass (the plan's
geometry once per distinct pose, cheaper scene checks, the mount's coarser
lit cells; ``docs/fast-simulator.md``).

Determinism
-----------
A scene's expected counts depend (by float32 rounding, ~1e-7 relative) on
the simulation it ran in, so simulations are fixed by the arguments: the
sorted positions cut into runs of ``batch``, with the objects and lightings
in the given order. The counts equal those of each group simulated alone (a
test compares them capture by capture). A run with any capture missing is
simulated for its missing groups and only the missing captures are stored.
Rerun with other ``positions``, ``objects`` or ``batch``, a rare count may
differ from a fresh build's (same noise seeds, means that differ in float32
rounding).
"""

from __future__ import annotations

import hashlib
import json
import time
import warnings
from functools import partial
from typing import Callable, Sequence

import numpy as np

from nlosplan._jax import jax, jnp
from nlosplan.denali import DENALI_OBJECTS, N_POSITIONS, SIZES, class_group, positions_xy
from nlosplan.errors import UserError
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.sensor_models.noise import CaptureNoise, floor_counts
from nlosplan.simulators.presets.denali import denali_scene
from nlosplan.simulators.scene import NLOSWarning
from nlosplan.data.denali_io import OBJECT_ALIASES
from nlosplan.data.records import capture_key, sensor_hash, zones_of

__all__ = ["MAX_SESSION_FLOOR_SD", "SCENES", "SCENES_PER_SIMULATION", "SOURCE", "build_dataset", "draw_captures",
           "scene_seed", "session_shift"]

#: Scenes a dataset can be built from.
SCENES = ("denali",)
#: ``source`` label of the captures.
SOURCE = "sim:fast"

Progress = Callable[[int, int, str], None]

#: Scenes in one simulation at most (memory: each scene holds its objects' surface samples): the objects and
#: lightings of a run of positions share one, as many objects as fit.
SCENES_PER_SIMULATION = 1200


def scene_seed(seed: int, obj: str, size: str, position: int, lights: str) -> int:
    """The noise seed of one scene, from the build seed and its labels alone (0 to 2**63 - 1)."""
    text = f"nlosplan-build|{int(seed)}|{obj}|{size}|{int(position)}|{lights}"
    return int.from_bytes(hashlib.blake2b(text.encode(), digest_size=8).digest(), "little") >> 1


#: Largest session floor spread a build takes (a fraction of the floor).
MAX_SESSION_FLOOR_SD = 0.5


def session_shift(seed: int, obj: str, size: str, lights: str, sd: float) -> float:
    """How far one capture session's floor sits from the sensor's, a fraction of the floor.

    A session is one object, size and lighting (DENALI records each such folder, every position and repeat of
    it, in one sitting): its floor is ``(1 + shift)`` times the sensor's for all its captures, ``shift = sd * z``
    with ``z`` standard normal drawn from the build seed and the session's labels alone (0 when ``sd`` is 0).
    """
    if sd == 0:
        return 0.0
    text = f"nlosplan-session|{int(seed)}|{obj}|{size}|{lights}"
    rng = np.random.default_rng(int.from_bytes(hashlib.blake2b(text.encode(), digest_size=8).digest(), "little"))
    return float(sd * rng.standard_normal())


@partial(jax.jit, static_argnums=(2, 3))
def _draw_batch(keys, means, repeats: int, noise: CaptureNoise):
    return jax.vmap(lambda k, m: noise.draw(k, jnp.broadcast_to(m, (repeats,) + m.shape)))(keys, means)


def draw_captures(means: np.ndarray, seeds: Sequence[int], repeats: int, sensor: SensorConfig) -> np.ndarray:
    """Captures of a batch of scenes, each from its own seed.

    Drawn by the sensor's :class:`~nlosplan.sensor_models.noise.CaptureNoise`.

    Parameters
    ----------
    means : ndarray, shape (N, rows, cols, bins)
        Expected counts.
    seeds : sequence of N ints
        Noise seeds (0 to 2**64 - 1), e.g. from :func:`scene_seed`.
    repeats : int
    sensor : SensorConfig
        Its noise model (Poisson, 24-bit clip).

    Returns
    -------
    ndarray of int64, shape (N, repeats, rows, cols, bins)
        Scene ``i`` equals ``CaptureNoise.of(sensor).draw(jax.random.key(seeds[i]), means[i] repeated)``.
    """
    keys = jax.vmap(jax.random.key)(jnp.asarray(np.asarray(seeds, dtype=np.uint64)))
    return np.asarray(_draw_batch(keys, jnp.asarray(means), int(repeats), CaptureNoise.of(sensor)))


def _check_list(name: str, values, allowed: Sequence) -> list:
    values = [values] if isinstance(values, str) else list(values)
    bad = [v for v in values if v not in allowed]
    if bad or not values:
        raise UserError(f"{name} {bad or values!r} not allowed; allowed: {', '.join(map(str, allowed))}")
    return list(dict.fromkeys(values))


def _check_positions(positions) -> list[int]:
    out = []
    for p in positions:
        if isinstance(p, bool) or not isinstance(p, (int, np.integer)) or not 0 <= p < N_POSITIONS:
            raise UserError(f"position {p!r} is not allowed; allowed: integers 0 to {N_POSITIONS - 1}")
        out.append(int(p))
    if not out:
        raise UserError("give at least one position")
    return sorted(set(out))


def _resolve(sensor) -> SensorConfig:
    if isinstance(sensor, str):
        from nlosplan.sensor_models import resolve_sensor

        return resolve_sensor(sensor)
    if not isinstance(sensor, SensorConfig):
        raise UserError(f"sensor must be a SensorConfig or a preset name, not {type(sensor).__name__}")
    return sensor


def build_dataset(store, *, scene: str = "denali", sensor, objects: Sequence[str] = DENALI_OBJECTS,
                  sizes: Sequence[str] = SIZES, positions: Sequence[int] = range(N_POSITIONS),
                  lights: Sequence[str] = ("off",), repeats: int = 3, fidelity="default", seed: int = 0,
                  reflectance: str = "retroreflective", scene_options: dict | None = None,
                  progress: Progress | None = None, batch: int = N_POSITIONS, session_floor_sd: float = 0.0) -> dict:
    """Simulate DENALI captures into a store, resumably.

    Parameters
    ----------
    store : CaptureStore
    scene : {"denali"}
    sensor : SensorConfig or str
        The sensor (or a preset name / sensor file).
    objects, sizes : sequence of str
        DENALI objects (DENALI's data names ``"i"``, ``"halfcircle"`` are accepted)
        and sizes ("4in", "8in").
    positions : sequence of int
        Gantry positions, 0..99.
    lights : sequence of {"on", "off"}
    repeats : int
        Poisson captures per scene (repeat labels 0..repeats-1).
    fidelity : str or dict
        Fast-simulator fidelity level or knobs.
    seed : int
        Build seed; scene noise seeds come from :func:`scene_seed`.
    reflectance : {"retroreflective", "lambertian"}
        Object reflectance model (shared by every scene).
    scene_options : dict, optional
        Further :func:`~nlosplan.simulators.denali_scene` keywords (``albedo``,
        ``lobe_fwhm_deg``, ``mount``, ``wall_albedo``, ``table_albedo``, ``tables``).
    progress : callable, optional
        ``progress(done, total, text)`` after each group of each run of positions, in captures.
    batch : int
        Positions per run (fixes the simulations, see the module notes); a simulation holds at most
        :data:`SCENES_PER_SIMULATION` scenes (memory).
    session_floor_sd : float
        Spread of the floor between capture sessions, a fraction of the floor (0 to
        :data:`MAX_SESSION_FLOOR_SD`): every capture of one object, size and lighting has its floor moved by
        the same :func:`session_shift`. 0 (the default here): every session has the sensor's floor. The
        command line's default is the scene model's (:func:`~nlosplan.simulators.presets.scene_model.session_floor_sd`:
        1.73 % for DENALI's unit).

    Returns
    -------
    dict
        ``captures_total``, ``captures_added``, ``captures_skipped`` (stored
        before), ``groups``, ``groups_skipped``, ``seconds``, ``simulate_seconds``,
        ``store_seconds``, ``captures_per_second`` (added / seconds), ``simulations`` and
        ``scenes_simulated`` (simulator calls and their scenes), ``scenes_per_second`` (simulated
        scenes / ``simulate_seconds``, scene construction and Poisson draws included), the
        sensor, its hash and zones, ``fidelity`` knobs, ``seed``, ``variant``, ``session_floor_sd``
        and the simulator ``warnings``.

    Examples
    --------
    >>> with CaptureStore("sim.sqlite", synchronous="NORMAL") as st:  # doctest: +SKIP
    ...     build_dataset(st, sensor="tmf8828-3x3-short", objects=["A", "7"], positions=range(10), repeats=3)
    """
    from nlosplan import __version__
    from nlosplan.simulators import expected_batch, resolve_fidelity

    t_start = time.perf_counter()
    if scene not in SCENES:
        raise UserError(f"unknown scene {scene!r} for a dataset; allowed: {', '.join(SCENES)}")
    sensor = _resolve(sensor)
    objects = [objects] if isinstance(objects, str) else list(objects)
    objects = _check_list("objects", [OBJECT_ALIASES.get(o, o) for o in objects], DENALI_OBJECTS)
    sizes, lights = _check_list("sizes", sizes, SIZES), _check_list("lights", lights, ("on", "off"))
    positions = _check_positions(positions)
    if isinstance(repeats, bool) or not isinstance(repeats, (int, np.integer)) or repeats < 1:
        raise UserError(f"repeats={repeats!r} must be an integer >= 1")
    if isinstance(batch, bool) or not isinstance(batch, (int, np.integer)) or batch < 1:
        raise UserError(f"batch={batch!r} must be an integer >= 1")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise UserError(f"seed={seed!r} must be an integer >= 0")
    sd = session_floor_sd
    if isinstance(sd, bool) or not isinstance(sd, (int, float, np.floating)) or not 0 <= sd <= MAX_SESSION_FLOOR_SD:
        raise UserError(f"session_floor_sd={sd!r} must be a number from 0 to {MAX_SESSION_FLOOR_SD:g} (a fraction "
                        "of the floor)")
    sd = float(sd)
    knobs = resolve_fidelity(fidelity).to_dict()
    options = {"reflectance": reflectance, **(scene_options or {})}
    denali_scene(objects[0], sizes[0], positions[0], lights[0], **options)  # check the options before any work
    variant_doc = {"scene": scene, "backend": "fast", "dtype": "float32", "options": options, "fidelity": knobs}
    if sd:   # captures with a session floor are another variant (without one, the variant of before)
        variant_doc["session_floor_sd"] = sd
    variant = hashlib.sha256(json.dumps(variant_doc, sort_keys=True).encode()).hexdigest()[:12]
    h, zones, xy = sensor_hash(sensor), zones_of(sensor), positions_xy()
    fidelity_label = fidelity if isinstance(fidelity, str) else json.dumps(knobs, sort_keys=True)
    stored = store.keys(source=SOURCE, sensor_hash=h, seed=int(seed), variant=variant)
    sim_meta = {"nlosplan": __version__, "jax": jax.__version__}
    total = len(objects) * len(sizes) * len(lights) * len(positions) * repeats
    done = added = skipped = groups_skipped = 0
    t_sim = t_store = 0.0
    messages: list[str] = []
    batches = [positions[i: i + batch] for i in range(0, len(positions), batch)]
    if progress:
        progress(0, total, "starting")

    def labels(obj, size, light, p, r):
        return dict(object=obj, size=size, class_group=class_group(obj), position=p, x=float(xy[p, 0]),
                    y=float(xy[p, 1]), lights=light, zones=zones, repeat=r, source=SOURCE, seed=int(seed),
                    variant=variant, scene=scene, backend="fast", fidelity=fidelity_label)

    # one build of these captures at a time: an identical build started meanwhile stops at once, before simulating
    identity = json.dumps([h, int(seed), variant, objects, sizes, positions, lights, int(repeats), batch])
    groups = [(obj, size, light) for obj in objects for size in sizes for light in lights]
    keys = {g: {(p, r): capture_key(labels(*g, p, r), h) for p in positions for r in range(repeats)} for g in groups}
    complete = {g for g in groups if all(k in stored for k in keys[g].values())}
    groups_skipped = len(complete)
    meshes = [(obj, size) for obj in objects for size in sizes]
    plan = None  # the last simulation's plan: the next one is padded to it (one compiled program for the build)
    n_sims = n_scenes = 0
    with store.writer(f"dataset build #{hashlib.sha256(identity.encode()).hexdigest()[:12]}"):
        for chunk in batches:
            per_sim = max(1, SCENES_PER_SIMULATION // (len(chunk) * len(lights)))
            for m0 in range(0, len(meshes), per_sim):
                todo = []  # (group, missing (p, r)) of the meshes of this simulation
                for obj, size in meshes[m0: m0 + per_sim]:
                    for light in lights:
                        g = (obj, size, light)
                        # stored meanwhile by another build (a concurrent one with other objects or positions) counts
                        missing = [] if g in complete else [
                            (p, r) for p in chunk for r in range(repeats)
                            if keys[g][(p, r)] not in stored and not store.has(keys[g][(p, r)])]
                        skipped += len(chunk) * repeats - len(missing)
                        done += len(chunk) * repeats - len(missing)
                        if missing:
                            todo.append((g, missing))
                if not todo:
                    if progress:
                        progress(done, total, f"positions {chunk[0]}-{chunk[-1]}: stored already")
                    continue
                t0 = time.perf_counter()
                # every lighting and object of these positions in one simulation: an object's light is the same
                # under both lightings and the mount's the same under every object, so each is computed once
                scenes = [denali_scene(obj, size, p, light, **options) for (obj, size, light), _ in todo for p in chunk]
                sim = expected_batch(scenes, sensor, fidelity=knobs, pad_to=plan)
                plan = sim.plan
                n_sims, n_scenes = n_sims + 1, n_scenes + len(scenes)
                messages += [w for w in sim.warnings if w not in messages]
                t_sim += time.perf_counter() - t0
                for i, ((obj, size, light), missing) in enumerate(todo):
                    t0 = time.perf_counter()
                    seeds = [scene_seed(seed, obj, size, p, light) for p in chunk]
                    rows = slice(i * len(chunk), (i + 1) * len(chunk))
                    shift = session_shift(seed, obj, size, light, sd)
                    means = sim.expected[rows]
                    if shift:
                        means = np.maximum(np.asarray(means) + shift * floor_counts(sensor, light == "on"), 0.0)
                    counts = draw_captures(means, seeds, repeats, sensor)
                    t1 = time.perf_counter()
                    index = {p: j for j, p in enumerate(chunk)}
                    items = [(counts[index[p], r], labels(obj, size, light, p, r),
                              {"scene_meta": scenes[rows][index[p]].meta, "scene_seed": seeds[index[p]],
                               "fidelity_knobs": knobs, "simulator": sim_meta, "session_floor_shift": shift})
                             for p, r in missing]
                    added += store.put_many(items, sensor=sensor).added
                    t_sim, t_store = t_sim + t1 - t0, t_store + time.perf_counter() - t1
                    done += len(missing)
                    if progress:
                        progress(done, total, f"{obj}_{size} lights {light}: positions {chunk[0]}-{chunk[-1]}")
    for m in messages:
        warnings.warn(m, NLOSWarning, stacklevel=2)
    seconds = time.perf_counter() - t_start
    return {"store": str(store.path), "scene": scene, "sensor": sensor.name, "sensor_hash": h, "zones": zones,
            "objects": objects, "sizes": sizes, "positions": positions, "lights": lights, "repeats": int(repeats),
            "fidelity": knobs, "seed": int(seed), "variant": variant, "scene_options": options,
            "session_floor_sd": sd,
            "groups": len(objects) * len(sizes) * len(lights), "groups_skipped": groups_skipped,
            "captures_total": total, "captures_added": added, "captures_skipped": skipped, "seconds": seconds,
            "simulate_seconds": t_sim, "store_seconds": t_store, "simulations": n_sims, "scenes_simulated": n_scenes,
            "scenes_per_second": n_scenes / t_sim if t_sim > 0 else 0.0,
            "captures_per_second": added / seconds if seconds > 0 else 0.0, "warnings": messages}
