"""`FastSimulator`: batches, parts and sampling on top of the JAX transport.

Compiled code is shared between simulators whose plans have the same
structure (same :class:`~nlosplan.simulators.fast.plan.PlanStatic` and
array shapes), so a loop over DENALI objects or positions compiles once.
"""

from __future__ import annotations

import dataclasses
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from nlosplan._jax import jax, jnp
from nlosplan.errors import UserError
from nlosplan.resources import default_threads
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.sensor_models.noise import CaptureNoise
from nlosplan.simulators.fast.plan import DYNAMIC_SENSOR_FIELDS, SimPlan, build_plan, pad_plan
from nlosplan.sensor_models.transient import DEPOSIT_METHODS, default_deposit, deposit_method
from nlosplan.simulators.fast.transport import forward, object_nodes, scene_counts, sensor_terms, with_exact_couplings
from nlosplan.simulators.scene import Scene

_FORWARD = jax.jit(forward, static_argnums=(0, 4))

def _batched(static, arrays, scene_p, sensor_p, parts):
    """Every scene under every sensor: (S, N, ...).

    Scenes run one after another inside the compiled call (``lax.map``): on a
    CPU the unbatched scatter-adds of the transport are about twice as fast
    as their ``vmap``-batched form. What does not depend on the scene (the
    impulse-response matrix, first bounce, crosstalk) is computed once per
    sensor. ``function()`` stays ``vmap``-able.
    """
    def per_sensor(sp):
        terms = sensor_terms(static, arrays, sp)  # once per sensor, shared by the scenes
        return jax.lax.map(lambda sc: scene_counts(static, arrays, sc, terms, parts), scene_p)

    with deposit_method(static.deposit):
        scene_p = with_exact_couplings(static, arrays, scene_p)
        return jax.lax.map(per_sensor, sensor_p)


_BATCHED = jax.jit(_batched, static_argnums=(0, 4))


def _sensor_terms(static, arrays, sensor_p):
    """:func:`~nlosplan.simulators.fast.transport.sensor_terms` of every sensor, leading axis (S,)."""
    with deposit_method(static.deposit):
        return jax.lax.map(lambda sp: sensor_terms(static, arrays, sp), sensor_p)


def _batched_terms(static, arrays, scene_p, terms, parts):
    """As :func:`_batched`, with the sensors' terms computed beforehand (:func:`_sensor_terms`).

    A simulator computes its sensors' terms once and reuses them in every call: a one-scene call then
    computes only the scene's objects.
    """
    with deposit_method(static.deposit):
        scene_p = with_exact_couplings(static, arrays, scene_p)
        return jax.lax.map(lambda t: jax.lax.map(lambda sc: scene_counts(static, arrays, sc, t, parts), scene_p), terms)


def _shared_nodes(static, arrays, scene_p, terms, only):
    """The object terms ``only`` of every scene under every sensor on the node grid: (S, N, Z, n_nodes)."""
    def per_sensor(t):
        bw, t0 = t["sp"]["bin_width_ps"], t["sp"]["start_offset_ps"]
        return jax.lax.map(lambda sc: object_nodes(static, arrays, sc, bw, t0, terms=only), scene_p)

    with deposit_method(static.deposit):
        scene_p = with_exact_couplings(static, arrays, scene_p, terms=only)
        return jax.lax.map(per_sensor, terms)


def _batched_shared(static, arrays, scene_p, terms, parts, only, nodes):
    """As :func:`_batched_terms`, with the object terms ``only`` given as nodes (S, N, Z, n_nodes) (:func:`_shared_nodes`)."""
    def per_sensor(tn):
        t, n = tn
        return jax.lax.map(lambda sn: scene_counts(static, arrays, sn[0], t, parts, shared=(only, sn[1])),
                           (scene_p, n))

    with deposit_method(static.deposit):
        rest = [k for k in range(len(static.objects)) if k not in only]
        scene_p = with_exact_couplings(static, arrays, scene_p, terms=rest)
        return jax.lax.map(per_sensor, (terms, nodes))


_TERMS = jax.jit(_sensor_terms, static_argnums=(0,))
_BATCHED_TERMS = jax.jit(_batched_terms, static_argnums=(0, 4))
_SHARED = jax.jit(_shared_nodes, static_argnums=(0, 4))
_BATCHED_SHARED = jax.jit(_batched_shared, static_argnums=(0, 4, 5))


def sensor_params(sensor: SensorConfig) -> dict:
    """The dynamic (traceable) fields of a sensor as floats."""
    return {k: float(getattr(sensor, k)) for k in DYNAMIC_SENSOR_FIELDS}


def scene_params(scene: Scene, object_index=None, albedo=None) -> dict:
    """The dynamic fields of a scene: object poses and albedos, lights.

    Parameters
    ----------
    scene : Scene
    object_index : sequence of int, optional
        The object of each transport term (default: one term per object).
    albedo : sequence of str, optional
        The attribute holding each term's albedo (default ``"albedo"``; the
        diffuse base of a retroreflective object uses ``"diffuse_albedo"``).
    """
    idx = list(range(len(scene.objects)) if object_index is None else object_index)
    attrs = ["albedo"] * len(idx) if albedo is None else list(albedo)
    return {
        "objects": [{"to_world": np.asarray(scene.objects[k].to_world), "albedo": getattr(scene.objects[k], a)}
                    for k, a in zip(idx, attrs)],
        "lights": 1.0 if scene.lights_on else 0.0,
    }


def _stack(items: list[dict]):
    return jax.tree_util.tree_map(lambda *xs: np.stack([np.asarray(x) for x in xs]), *items)


def to_jax(tree, dtype):
    """A tree of arrays as JAX arrays: floats in ``dtype``, integers as int32, booleans kept (plans, parameters).

    Cast by NumPy, then put on the device as they are: ``jnp.asarray(a, dtype)`` runs a conversion primitive per
    leaf (0.45 ms each; a world reference's 60 chunks of scene parameters hold 5,400 leaves).
    """
    floats = np.dtype(jnp.dtype(dtype).name)

    def conv(a):
        a = np.asarray(a)
        if a.dtype == bool:
            return jax.device_put(a)
        if np.issubdtype(a.dtype, np.integer):
            return jax.device_put(a.astype(np.int32, copy=False))
        return jax.device_put(a.astype(floats, copy=False))

    return jax.tree_util.tree_map(conv, tree)


def _map_threads(fn, items: list, threads: int):
    """``fn`` over ``items`` in order, on up to ``threads`` threads (a generator; one thread: in this one)."""
    threads = min(int(threads), len(items))
    if threads > 1:
        with ThreadPoolExecutor(threads, thread_name_prefix="nlosplan-sim") as pool:
            yield from pool.map(fn, items)
    else:
        for item in items:
            yield fn(item)


class FastSimulator:
    """The fast (JAX) backend for a batch of scenes and sensors.

    Parameters
    ----------
    scenes : Scene or list of Scene
        One scene, or scenes that share the rig and the objects' reflectance
        models and differ in object meshes, poses, albedos and lights (e.g.
        every DENALI object at every position).
    sensor : SensorConfig
    fidelity : str, dict or Fidelity
        Quadrature/sampling level (``draft``, ``low``, ``default``, ``high``,
        ``reference``) or explicit knobs.
    zones : list of (row, col), optional
        Compute only these zones.
    prune : bool
        Leave out what the scene does not need (see :meth:`explain`).
    dtype : {"float32", "float64"}
    sensors : list of SensorConfig, optional
        Evaluate every scene under each of these sensors (they may differ
        only in bin width, offset, pulse/jitter width, photon scale,
        iterations, ambient, dark and crosstalk); ``sensor`` is ignored then.
    chunk : int
        Scenes per compiled batch call (memory bound).
    threads : int, optional
        Chunks run at once, each on its own thread (default :func:`~nlosplan.resources.default_threads`: the usable cores, or
        ``$NLOSPLAN_SIM_THREADS``; 1 in design workers). The first call's first chunk runs alone (it
        compiles); results are the same as with one thread, in the same order.
    deposit : {"kernel", "window", "scatter"}, optional
        How arrivals are added onto the node grid (:data:`~nlosplan.sensor_models.transient.DEPOSIT_METHODS`):
        the compiled C++ loops (:mod:`~nlosplan.sensor_models.compiled`, built on first use; ``"kernel"`` also
        sums a Lambertian object's convolved legs in C++ instead of FFTs), one windowed XLA scatter-add, or
        the two scalar ones of before issue 20 (``bench simulate --baseline``); equal up to float rounding.
        Default: the kernels where they build, else the windowed scatter-add (with a warning that says why).
    cache_chunks : bool
        Build each chunk's parameters once, on the host, and the sensors' terms (impulse-response matrix,
        first bounce, crosstalk) once, and reuse them in every call (default). ``False`` is the path of
        before issue 20: every call gathers each chunk's parameters leaf by leaf on the device (about
        0.4 ms per leaf on this CPU, so 3-10 ms for one scene) and recomputes the sensors' terms, kept for
        ``bench simulate --baseline``. Equal within float32 rounding.
    share : bool
        Compute an object term that is identical in many scenes of the batch (same mesh, pose and albedo:
        e.g. the gantry's mount and plate in every object scene at one position) once per distinct pose,
        and add it to each scene's other terms on the node grid, before the zone terms and the time walk
        (default; with ``cache_chunks`` only). A term is shared when it has at most half as many distinct
        poses as there are scenes; terms that repeat over the same scenes (the mount and its plate at each
        position) are computed together, each such class once per distinct combination (so the mount is
        computed once per position however many objects and lightings share it). Equal to ``share=False``
        within float32 rounding.
    pad_to : SimPlan, optional
        A plan compiled before (e.g. the previous batch's ``plan``): this batch's object-term sizes are raised
        to its sizes where smaller (:func:`~nlosplan.simulators.fast.plan.pad_plan`), so a sweep over objects
        or positions reuses one compiled program instead of compiling one per batch. Equal within float32
        rounding.
    min_support_sigma_ps : float
        Plan the impulse response's support for at least this Gaussian sigma, ps
        (:func:`~nlosplan.simulators.fast.plan.build_plan`): batches of sensors with different jitter then share
        one compiled program. Equal within float32 rounding.

    Examples
    --------
    >>> from nlosplan.simulators import corner_scene
    >>> from nlosplan.sensor_models import preset
    >>> sim = FastSimulator(corner_scene(), preset("tmf8828-3x3-short"), fidelity="draft")
    >>> sim.expected().shape
    (3, 3, 128)
    """

    def __init__(self, scenes, sensor: SensorConfig | None = None, *, fidelity="default", zones=None,
                 prune: bool = True, dtype="float32", sensors=None, chunk: int = 25, deposit: str | None = None,
                 cache_chunks: bool = True, share: bool = True, threads: int | None = None,
                 pad_to: SimPlan | None = None, min_support_sigma_ps: float = 0.0):
        self.scenes = [scenes] if isinstance(scenes, Scene) else list(scenes)
        self.sensors = list(sensors) if sensors is not None else [sensor]
        if any(not isinstance(s, SensorConfig) for s in self.sensors):
            raise UserError("sensor must be a SensorConfig (a preset or a loaded sensor file)")
        if str(dtype) not in ("float32", "float64"):
            raise UserError(f"dtype={dtype!r} is not supported; allowed: float32, float64")
        self.dtype = jnp.dtype(str(dtype))
        self.single_scene = isinstance(scenes, Scene)
        self.single_sensor = sensors is None
        if deposit is None:
            deposit = default_deposit()
        if deposit not in DEPOSIT_METHODS:
            raise UserError(f"deposit={deposit!r} is not supported; allowed: {', '.join(DEPOSIT_METHODS)}")
        self.plan: SimPlan = pad_plan(build_plan(self.scenes, self.sensors, fidelity, zones=zones, prune=prune,
                                                min_support_sigma_ps=min_support_sigma_ps), pad_to)
        if deposit != self.plan.static.deposit:
            self.plan = dataclasses.replace(self.plan, static=dataclasses.replace(self.plan.static, deposit=deposit))
        self.chunk = max(1, int(chunk))
        self.threads = default_threads() if threads is None else int(threads)
        if self.threads < 1:
            raise UserError(f"threads={threads!r}: at least 1")
        self._arrays = to_jax(self.plan.arrays, self.dtype)
        self._params = None
        self.cache_chunks = bool(cache_chunks)
        self._chunks = None
        self._sensor_terms = None
        self.share = bool(share)
        self._shared = None
        self._scene_np = None
        self._warm = set()  # the values of `parts` a call has run (and compiled) with here

    # ------------------------------------------------------------ parameters
    def params(self) -> tuple[dict, dict]:
        """Batched dynamic parameters ``(scene_p, sensor_p)`` with leading axes (N,) and (S,).

        ``scene_p["objects"][k]`` holds the pose ``to_world`` (4, 4), the
        ``albedo``, the object's surface quadrature (``points``, ``normals``,
        ``areas``, object frame) and the wall cells needing the exact
        near-wall coupling (``near1``, ``near2``) of every scene.
        """
        plan = self.plan
        per_scene = [scene_params(s, plan.object_index, plan.object_albedo) for s in self.scenes]
        for k, (samples, index) in enumerate(zip(plan.object_samples, plan.object_mesh_index)):
            near = plan.object_near_index[k]
            for j, (sp, i) in enumerate(zip(per_scene, index)):
                pts, nrm, area = samples[i]
                sp["objects"][k].update(points=pts, normals=nrm, areas=area,
                                        **{f"near{leg}": idx[j] for leg, idx in near.items()})
        return _stack(per_scene), _stack([sensor_params(s) for s in self.sensors])

    def function(self, parts: bool = False):
        """Pure ``f(scene_p, sensor_p) -> counts (Z, bins)`` for one scene and sensor.

        Differentiate it with ``jax.grad`` (object poses, albedos, any dynamic
        sensor field) or ``vmap`` it; the plan's arrays are closed over.
        """
        static, arrays = self.plan.static, self._arrays
        return lambda scene_p, sensor_p: forward(static, arrays, scene_p, sensor_p, parts)

    def explain(self) -> str:
        """The plan: computed and left-out terms with reasons."""
        return self.plan.explain()

    # ------------------------------------------------------------ evaluation
    def _jax_params(self):
        if self._params is None:  # built once: the scenes and sensors are fixed
            scene_p, sensor_p = self.params()
            self._params = to_jax(scene_p, self.dtype), to_jax(sensor_p, self.dtype)
        return self._params

    def _chunk_index(self) -> list[tuple[np.ndarray, int]]:
        """Scene indices of each compiled call, shape ``(chunk,)`` (the last one padded with its last scene), and the count kept."""
        n = len(self.scenes)
        if n <= self.chunk:
            return [(np.arange(n), n)]
        return [(np.arange(start, start + self.chunk).clip(max=min(start + self.chunk, n) - 1),
                 min(self.chunk, n - start)) for start in range(0, n, self.chunk)]

    def _scene_arrays(self) -> dict:
        """The scenes' parameters of :meth:`params` as host arrays, built once.

        The chunks and the shared terms both slice them.
        """
        if self._scene_np is None:
            self._scene_np = self.params()[0]
        return self._scene_np

    def _chunk_params(self) -> list[tuple[dict, int]]:
        """Each chunk's scene parameters as JAX arrays with the number of its scenes kept, built once.

        The chunks are sliced on the host (NumPy) before the transfer: slicing the device arrays costs
        one gather dispatch per leaf and chunk on every call.
        """
        if self._chunks is None:
            scene_np = self._scene_arrays()
            self._chunks = [(to_jax(jax.tree_util.tree_map(lambda a: np.asarray(a)[idx], scene_np), self.dtype), keep)
                            for idx, keep in self._chunk_index()]
        return self._chunks

    def shared_terms(self) -> tuple[tuple[int, ...], np.ndarray, np.ndarray] | None:
        """The object terms computed once per distinct pose (see ``share``), or None.

        Returns
        -------
        terms : tuple of int
            Indices into the plan's object terms.
        first : ndarray of int, shape (U,)
            A scene of each distinct combination of those terms' meshes, poses and albedos.
        group : ndarray of int, shape (N,)
            Each scene's combination (an index into ``first``).
        """
        plan, n = self.plan, len(self.scenes)
        if not (self.share and self.cache_chunks) or n < 2:
            return None
        terms, keys = [], []
        for k, (obj, attr) in enumerate(zip(plan.object_index, plan.object_albedo)):
            near = sorted(plan.object_near_index[k].items())
            col = [(int(plan.object_mesh_index[k][j]), np.asarray(sc.objects[obj].to_world, np.float64).tobytes(),
                    float(getattr(sc.objects[obj], attr)), tuple(np.asarray(idx[j]).tobytes() for _, idx in near))
                   for j, sc in enumerate(self.scenes)]
            if 2 * len(set(col)) <= n:
                terms.append(k)
                keys.append(col)
        if not terms:
            return None
        index: dict = {}
        group = np.array([index.setdefault(key, len(index)) for key in zip(*keys)])
        first = np.array([int(np.flatnonzero(group == g)[0]) for g in range(len(index))])
        return tuple(terms), first, group

    def shared_classes(self) -> list[tuple[tuple[int, ...], np.ndarray, np.ndarray]]:
        """:meth:`shared_terms` split into classes of terms that repeat over the same scenes.

        The mount and its plate repeat wherever the position does, an object's two terms wherever the object
        and position do (e.g. both lightings): each class is computed once per distinct combination of its own
        terms, not of every shared term together.

        Returns
        -------
        list of (terms, first, group)
            As :meth:`shared_terms`, one per class, in term order (empty when nothing is shared).
        """
        share = self.shared_terms()
        if share is None:
            return []
        terms, first, group = share
        plan = self.plan
        classes: dict = {}
        for k in terms:
            obj, attr = plan.object_index[k], plan.object_albedo[k]
            near = sorted(plan.object_near_index[k].items())
            col = [(int(plan.object_mesh_index[k][j]), np.asarray(sc.objects[obj].to_world, np.float64).tobytes(),
                    float(getattr(sc.objects[obj], attr)), tuple(np.asarray(idx[j]).tobytes() for _, idx in near))
                   for j, sc in enumerate(self.scenes)]
            index: dict = {}
            g = np.array([index.setdefault(key, len(index)) for key in col])
            classes.setdefault(g.tobytes(), (g, []))[1].append(k)
        out = []
        for g, ks in classes.values():
            out.append((tuple(ks), np.array([int(np.flatnonzero(g == u)[0]) for u in range(int(g.max()) + 1)]), g))
        return out

    def _shared_node_table(self, terms: dict):
        """``(terms, [(group (N,), nodes (S, U, Z, n_nodes) ndarray) per class])`` of :meth:`shared_classes`, computed
        once, or None."""
        if self._shared is None:
            classes = self.shared_classes()
            if not classes:
                self._shared = False
            else:
                scene_np = self._scene_arrays()
                tables = []
                for only, first, group in classes:
                    def one(start, only=only, first=first):
                        idx = first[np.arange(start, start + self.chunk).clip(max=len(first) - 1)]
                        chunk_p = to_jax(jax.tree_util.tree_map(lambda a: np.asarray(a)[idx], scene_np), self.dtype)
                        keep = min(self.chunk, len(first) - start)
                        return np.asarray(_SHARED(self.plan.static, self._arrays, chunk_p, terms, only))[:, :keep]

                    # chunks of the scenes' shape (one compile each way); the first alone (it compiles), the others
                    # on the simulator's threads, as in _run
                    starts = list(range(0, len(first), self.chunk))
                    outs = [one(starts.pop(0))]
                    outs += _map_threads(one, starts, self.threads)
                    tables.append((group, np.concatenate(outs, axis=1)))
                self._shared = (tuple(sorted(k for c in classes for k in c[0])), tables)
        return self._shared or None

    def _run(self, parts: bool, progress=None):
        static = self.plan.static
        if self.cache_chunks:
            terms = self._terms()
            chunks = self._chunk_params()
            shared = self._shared_node_table(terms)
            if shared is None:
                run = lambda chunk_p, idx: _BATCHED_TERMS(static, self._arrays, chunk_p, terms, parts)  # noqa: E731
            else:
                only, tables = shared
                run = lambda chunk_p, idx: _BATCHED_SHARED(  # noqa: E731
                    static, self._arrays, chunk_p, terms, parts, only,
                    jnp.asarray(sum(nodes[:, group[idx]] for group, nodes in tables), self.dtype))
        else:  # before issue 20: the chunks gathered from the device arrays and the sensor terms, every call
            scene_p, sensor_p = self._jax_params()
            chunks = [(jax.tree_util.tree_map(lambda a: a[idx], scene_p), keep) for idx, keep in self._chunk_index()]
            run = lambda chunk_p, idx: _BATCHED(static, self._arrays, chunk_p, sensor_p, parts)  # noqa: E731
        jobs = [(chunk_p, keep, idx) for (chunk_p, keep), (idx, _) in zip(chunks, self._chunk_index())]

        def one(job):
            chunk_p, keep, idx = job
            return jax.tree_util.tree_map(lambda a: np.asarray(a)[:, :keep], run(chunk_p, idx))

        outs = []

        def done(out):
            outs.append(out)
            if progress is not None:
                progress(min(len(self.scenes), len(outs) * self.chunk), len(self.scenes))

        if parts not in self._warm:  # alone: the first call compiles (once per plan structure and process)
            done(one(jobs.pop(0)))
            self._warm.add(parts)
        for out in _map_threads(one, jobs, self.threads):
            done(out)
        return jax.tree_util.tree_map(lambda *xs: np.concatenate(xs, axis=1), *outs)

    def _terms(self) -> dict:
        """The sensors' terms (:func:`~nlosplan.simulators.fast.transport.sensor_terms`), leading axis (S,), computed once."""
        if self._sensor_terms is None:
            sensor_p = to_jax(_stack([sensor_params(s) for s in self.sensors]), self.dtype)
            self._sensor_terms = _TERMS(self.plan.static, self._arrays, sensor_p)
        return self._sensor_terms

    def _shape(self, a: np.ndarray) -> np.ndarray:
        """(S, N, Z, B) -> drop single batch axes; zones -> (rows, cols) when all are output."""
        s = self.plan.sensor
        if self.plan.full_grid:
            a = a.reshape(a.shape[:2] + (s.zones_rows, s.zones_cols, a.shape[-1]))
        if self.single_scene:
            a = a[:, 0]
        if self.single_sensor:
            a = a[0]
        return a

    def expected(self, parts: bool = False, progress=None):
        """Expected counts.

        Parameters
        ----------
        parts : bool
            Also the linear parts.
        progress : callable, optional
            Called as ``progress(scenes_done, scenes)`` after each compiled batch call.

        Returns
        -------
        ndarray, shape ([S,] [N,] rows, cols, bins) or ([S,] [N,] zones, bins)
            ``S`` only when ``sensors`` was given, ``N`` only for a list of
            scenes; zones as ``(rows, cols)`` unless a subset was requested.
        dict of such arrays (with ``parts``)
            ``counts`` and the linear parts ``direct``, ``object``,
            ``floor`` (dark + ambient), ``crosstalk`` (before pile-up and clipping).
        """
        out = self._run(parts, progress)
        if parts:
            counts, prt = out
            return {"counts": self._shape(counts), **{k: self._shape(v) for k, v in prt.items()}}
        return self._shape(out)

    def sample(self, key, repeats: int = 1) -> np.ndarray:
        """Poisson captures of the expected counts, shape ``(repeats, *expected().shape)``, int64.

        Parameters
        ----------
        key : jax random key or int
        repeats : int
        """
        if isinstance(key, (int, np.integer)):
            key = jax.random.key(int(key))
        if int(repeats) < 1:
            raise UserError(f"repeats={repeats} must be >= 1")
        mean = jnp.asarray(self.expected())
        mean = jnp.broadcast_to(mean, (int(repeats),) + mean.shape)
        return np.asarray(CaptureNoise.of(self.plan.sensor).draw(key, mean))
