"""Run a capture plan on a rig (real or emulated) or dry, storing every capture once.

Executor (STYLE.md 1)
---------------------
:class:`Executor` drives a plan generator (:mod:`~nlosplan.hardware.commands`)
against a :class:`~nlosplan.hardware.rig.Rig` and a
:class:`~nlosplan.data.store.CaptureStore`:

- ``Move`` and ``SetLights`` are lazy: the gantry moves and the lights change
  right before the next capture that is actually taken.
- Each ``Capture`` gets a step number (0, 1, ... in plan order) and the store
  key ``<run id>/<step>`` (the ``capture_id`` label). A capture already in the
  store is sent back from it (``resumed=True``) without moving or measuring:
  a run killed at any point (even SIGKILL) resumes where it stopped, with
  nothing lost or stored twice. A stored capture whose commanded position
  differs from the plan's is refused (a different plan under the same run id).
- Every capture is committed in one transaction, with its metadata: run id,
  step, plan, sensor and firmware configuration, commanded and reported
  position, timestamps, lights, repeat, frame counters, and the run's frame
  retries and sensor reconnects so far (``run_faults``; what the live page shows).
- A failed frame read (timeout, garbled link, unplug) reconnects the sensor
  and retries (``retries`` times); gantry errors and alarms end the run.
- Errors are thrown into the plan (so :func:`~nlosplan.hardware.plans.finalize_wrapper`
  cleanups run), then the executor's own finalize step always runs: stop the
  sensor, park the gantry (not when it is in alarm), also on Ctrl-C.
- ``Checkpoint`` is where a pause request (:meth:`Executor.request_pause`, or
  ``pause_when()`` returning true, e.g. a pause file) waits.

Dry run
-------
:func:`dry_run` runs a plan without hardware: it lists the moves, checks every
target against the gantry limits and, on the DENALI geometry, that no position
puts the object in the LiDAR's direct field of view, and estimates travel and time.
"""

from __future__ import annotations

import math
import signal
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import datetime, timezone
from typing import Callable

from nlosplan.errors import UserError
from nlosplan.hardware.commands import Capture, CaptureResult, Checkpoint, Move, Plan, SetLights
from nlosplan.hardware.transport import ConnectionLost, DeviceTimeout

__all__ = ["DryRunReport", "Executor", "RunContext", "RunSummary", "capture_id", "dry_run", "view_problem"]


#: Seconds of finalize that no interrupt can cut short (then a third Ctrl-C can: a device that does not answer).
FINALIZE_GRACE_S = 3.0


def _utc() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


def capture_id(run_id: str, step: int) -> str:
    """The ``capture_id`` label of a run's step (its store key part)."""
    return f"{run_id}/{int(step):06d}"


@dataclass(frozen=True)
class RunContext:
    """What a run captures: the labels every capture carries.

    Attributes
    ----------
    object, size : str
        The hidden object and its size label (DENALI objects derive their class group).
    class_group : str, optional
        Needed for objects that are not DENALI's.
    lights : bool
        Lights state before any ``SetLights``.
    source : str
        ``rig`` for real captures, ``emulated:rig`` for the emulators.
    plan : str
        The plan's description (stored with every capture).
    plan_total : int, optional
        Captures the plan will make, when known (for ``rig status``).
    plan_spec : dict, optional
        How to rebuild the plan (stored with step 0, for ``rig status``).
    """

    object: str
    size: str
    class_group: str | None = None
    lights: bool = False
    source: str = "rig"
    plan: str = ""
    plan_total: int | None = None
    plan_spec: dict | None = None


@dataclass
class RunSummary:
    """What a run did."""

    run_id: str
    captured: int = 0
    resumed: int = 0
    moves: int = 0
    retries: int = 0
    reconnects: int = 0
    checkpoints: int = 0
    steps: int = 0
    completed: bool = False
    error: str | None = None
    finalize: list = field(default_factory=list)
    sensor_stats: dict = field(default_factory=dict)
    seconds: float = 0.0

    def to_dict(self) -> dict:
        return dict(self.__dict__)


def view_problem(sensor_config, obj: str, size: str, x_mm: float, y_mm: float) -> str | None:
    """On the DENALI geometry: a message when the object at (x, y) mm is in the LiDAR's direct view, else None."""
    from nlosplan.simulators import scene_at
    from nlosplan.simulators import explain

    warnings = explain(scene_at(obj, size, x_mm, y_mm), sensor_config, fidelity="draft").warnings
    hits = [w for w in warnings if "direct field of view" in w]
    return f"({x_mm:.1f}, {y_mm:.1f}) mm: {hits[0]}" if hits else None


class Executor:
    """Runs plans on a rig and stores their captures.

    Parameters
    ----------
    rig : Rig
        Sensor, gantry, lights and their configuration (:mod:`nlosplan.hardware.rig`).
    store : CaptureStore
    run_id : str
        Names the run; the same id resumes it.
    context : RunContext
    retries : int
        Frame-read retries (each after reconnecting the sensor).
    check_view : bool
        Refuse moves that put the object in the LiDAR's direct view (DENALI geometry only).
    on_capture : callable, optional
        Called with each :class:`CaptureResult` (progress).
    pause_when : callable, optional
        Polled at checkpoints; the run waits while it returns true.
    """

    def __init__(self, rig, store, *, run_id: str, context: RunContext, retries: int = 3, check_view: bool = True,
                 on_capture: Callable[[CaptureResult], None] | None = None,
                 pause_when: Callable[[], bool] | None = None) -> None:
        if not run_id or "/" in run_id:
            raise UserError(f"run id {run_id!r} must be non-empty and without '/'")
        self.rig, self.store, self.run_id, self.ctx = rig, store, run_id, context
        self.retries, self.check_view = int(retries), check_view
        self.on_capture, self.pause_when = on_capture, pause_when
        self._pause = threading.Event()
        self.summary = RunSummary(run_id)
        self._target: tuple[float, float] | None = None
        self._settle = 0.0
        self._at: tuple[float, float] | None = None
        self._want_lights = bool(context.lights)
        self._view_ok: dict = {}
        self._step = 0
        ids = store.labels(source=context.source)["capture_id"] if store.count(source=context.source) else []
        self._run_ids = {c for c in ids if c.startswith(f"{run_id}/")}   # this run's stored steps

    # ------------------------------------------------------------------ pause
    def request_pause(self) -> None:
        """Pause at the next checkpoint (thread-safe)."""
        self._pause.set()

    def resume(self) -> None:
        """Go on after a pause."""
        self._pause.clear()

    def _paused(self) -> bool:
        return self._pause.is_set() or bool(self.pause_when and self.pause_when())

    # ------------------------------------------------------------------ run
    def run(self, plan: Plan) -> RunSummary:
        """Run ``plan`` to its end; the finalize step always runs.

        Returns
        -------
        RunSummary

        Raises
        ------
        Whatever ended the run (after finalize): UserError, GrblAlarm, SensorError, KeyboardInterrupt, ...
        """
        t0 = time.monotonic()
        reply, throw = None, None
        try:
            while True:
                try:
                    cmd = plan.throw(throw) if throw is not None else plan.send(reply)
                except StopIteration:
                    break
                throw, reply = None, None
                try:
                    reply = self._do(cmd)
                except BaseException as exc:  # noqa: BLE001 - thrown into the plan for its cleanup, then re-raised
                    throw = exc
            self.summary.completed = True
        except BaseException as exc:
            self.summary.error = f"{type(exc).__name__}: {exc}"
            raise
        finally:
            held: list = []
            with _signals_held(held):   # a second Ctrl-C (or a SIGTERM) cannot cut finalize short
                self._finalize()
            self.summary.seconds = time.monotonic() - t0
            self.summary.sensor_stats = dict(self.rig.sensor.stats)
            if held and self.summary.error is None:
                signal.raise_signal(held[0])   # the plan ended, then came an interrupt: it still ends the command
        return self.summary

    def _do(self, cmd):
        if isinstance(cmd, Move):
            self._check_move(cmd.x_mm, cmd.y_mm)
            self._target, self._settle = (cmd.x_mm, cmd.y_mm), cmd.settle_s
            return None
        if isinstance(cmd, SetLights):
            self._want_lights = cmd.on
            return None
        if isinstance(cmd, Checkpoint):
            self.summary.checkpoints += 1
            while self._paused():
                time.sleep(0.1)
            return None
        if isinstance(cmd, Capture):
            return self._capture(cmd)
        raise UserError(f"a plan yielded {cmd!r}; allowed: Move, Capture, SetLights, Checkpoint")

    def _check_move(self, x: float, y: float) -> None:
        self.rig.gantry.check_limits(x, y)
        if self.check_view and self.rig.geometry == "denali":
            key = (round(x, 1), round(y, 1))
            if key not in self._view_ok:
                self._view_ok[key] = view_problem(self.rig.sensor_config, self.ctx.object, self.ctx.size, x, y)
            if self._view_ok[key]:
                raise UserError(f"refusing to move: {self._view_ok[key]}")

    # ------------------------------------------------------------------ capture
    def _labels(self, cmd: Capture, step: int) -> dict:
        from nlosplan.denali import grid_index, label_xy

        x, y = self._target
        labels = {"object": self.ctx.object, "size": self.ctx.size, "position": grid_index(x, y),
                  "lights": "on" if self._want_lights else "off", "repeat": cmd.repeat, "source": self.ctx.source,
                  "capture_id": capture_id(self.run_id, step)}
        if self.ctx.class_group:
            labels["class_group"] = self.ctx.class_group
        if self.rig.geometry == "denali":
            labels["x"], labels["y"] = label_xy(x, y)
        labels.update(cmd.labels)
        return labels

    def _capture(self, cmd: Capture) -> CaptureResult:
        from nlosplan.data.records import capture_key

        if self._target is None:
            raise UserError("the plan asked for a capture before any Move")
        step = self._step
        self._step += 1
        self.summary.steps = self._step
        labels = self._labels(cmd, step)
        key = capture_key(labels, self.rig.sensor_config)
        if self.store.has(key) or capture_id(self.run_id, step) in self._run_ids:
            result = self._stored(key, step, cmd)
            self.summary.resumed += 1
        else:
            result = self._take(cmd, step, labels, key)
            self.summary.captured += 1
        if self.on_capture:
            self.on_capture(result)
        return result

    def _stored(self, key: str, step: int, cmd: Capture) -> CaptureResult:
        found = next(self.store.iter_captures(capture_id=capture_id(self.run_id, step)), None)
        if found is None or found.key != key:
            raise UserError(f"run {self.run_id!r} step {step}: the store holds another capture under this id; "
                            "use a new --run id")
        commanded = tuple(found.meta.get("commanded_mm") or ())
        if len(commanded) != 2 or any(abs(a - b) > 1e-6 for a, b in zip(commanded, self._target)):
            raise UserError(f"run {self.run_id!r} step {step} was captured at {commanded} mm but the plan now asks "
                            f"for {self._target} mm: this is a different plan; use a new --run id")
        rep = found.meta.get("reported_mm")
        return CaptureResult(step, cmd.repeat, key, found.id, found.histogram, self._target,
                             None if rep is None else tuple(rep), _xy(found.labels), resumed=True)

    def _bring_to_target(self) -> None:
        rig = self.rig
        if not rig.sensor.measuring and rig.sensor.zones is not None:  # stopped by an earlier run's finalize
            rig.sensor.start(rig.sensor.zones, rig.sensor.range_mode)
        if rig.lights.state is not self._want_lights:
            rig.lights.set(self._want_lights)
        if self._at != self._target:
            self._at = None
            rig.gantry.move_to(*self._target, feed_mm_min=rig.feed_mm_min)
            self._at = self._target
            self.summary.moves += 1
            if self._settle:
                time.sleep(self._settle)

    def _take(self, cmd: Capture, step: int, labels: dict, key: str) -> CaptureResult:
        from nlosplan.hardware.tmf8828 import SensorError, SensorGarbage

        rig = self.rig
        self._bring_to_target()
        t_start = _utc()
        frame = None
        for attempt in range(self.retries + 1):
            try:
                frame = rig.sensor.read_frame(fresh=True)
                break
            except SensorGarbage:
                raise   # what is on the port does not change by reconnecting
            except (SensorError, ConnectionLost, DeviceTimeout) as exc:
                if attempt == self.retries:
                    raise SensorError(f"no frame at step {step} after {self.retries} retries: {exc}") from None
                self.summary.retries += 1
                rig.sensor.reconnect()
                self.summary.reconnects += 1
        pos = rig.gantry.where()
        reported = [round(v, 4) for v in pos.xy_mm]
        meta = {
            "run_id": self.run_id, "step": step, "plan": self.ctx.plan, "plan_total": self.ctx.plan_total,
            "commanded_mm": list(self._target), "reported_mm": reported, "gantry_raw": pos.raw,
            "gantry_state": pos.state, "settle_s": self._settle, "repeat": cmd.repeat, "lights": labels["lights"],
            "t_capture_start_utc": t_start, "t_capture_end_utc": _utc(),
            "sensor": {"port": rig.sensor.port_name, **rig.sensor.firmware_config()},
            "gantry": {**rig.gantry.describe(), "feed_mm_min": rig.feed_mm_min},
            "frame": {"results": [o.to_dict() for o in frame.results], "assembler": rig.sensor.stats},
            "emulated": list(rig.emulated), "run_faults": {"retries": self.summary.retries,
                                                           "reconnects": self.summary.reconnects},
            **cmd.meta,
        }
        if step == 0 and self.ctx.plan_spec is not None:
            meta["plan_spec"] = self.ctx.plan_spec
        sid = self.store.put(frame.counts, labels, sensor=rig.sensor_config, meta=meta)
        return CaptureResult(step, cmd.repeat, key, sid, frame.counts, self._target, tuple(reported),
                             (labels.get("x"), labels.get("y")) if "x" in labels else None)

    # ------------------------------------------------------------------ finalize
    def _finalize(self) -> None:
        """Stop the sensor, park the gantry (not when it is blocked); every outcome is noted, with where it is."""
        notes = self.summary.finalize
        try:
            self.rig.sensor.stop()
            notes.append("sensor stopped")
        except Exception as exc:  # noqa: BLE001 - finalize must go on to the gantry
            notes.append(f"sensor stop failed: {exc}")
        park = self.rig.park_mm
        gantry = self.rig.gantry
        blocked = gantry.blocked()
        if blocked is not None:
            notes.append(f"gantry {blocked}: not parked, last reported at {_at(gantry.last_xy)}")
            return
        if park is None:
            notes.append(f"gantry left at {_at(gantry.last_xy)} (no parking)")
            return
        try:
            pos = gantry.move_to(*park, feed_mm_min=self.rig.feed_mm_min)
            notes.append(f"gantry parked at ({park[0]:g}, {park[1]:g}) mm")
            if pos is not None and max(abs(a - b) for a, b in zip(pos.xy_mm, park)) > 0.01:
                notes.append(f"gantry reports {_at(pos.xy_mm)}")
        except BaseException as exc:  # noqa: BLE001 - reported, the run's own error goes on
            notes.append(f"gantry not parked: {exc}; last reported at {_at(gantry.last_xy)}")


@contextmanager
def _signals_held(held: list):
    """SIGINT and SIGTERM wait while the block runs (appended to ``held``), in the main thread; handlers restored
    after. Finalize (stop the sensor, park the gantry) runs to its end through repeated Ctrl-C; only a third one
    after :data:`FINALIZE_GRACE_S` stops it (a device that no longer answers; a move may wait up to its timeout)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    t0 = time.monotonic()

    def hold(signum, frame):
        held.append(signum)
        if len(held) >= 3 and time.monotonic() - t0 > FINALIZE_GRACE_S:   # finalize stuck on a dead device
            raise KeyboardInterrupt("finalize cut short by a third interrupt: the gantry may not be parked")

    old = {s: signal.signal(s, hold) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, handler in old.items():
            signal.signal(s, signal.SIG_DFL if handler is None else handler)


def _at(xy) -> str:
    return "an unknown position" if xy is None else f"({xy[0]:.3f}, {xy[1]:.3f}) mm"


def _xy(labels: dict):
    x, y = labels.get("x"), labels.get("y")
    return None if x is None or (isinstance(x, float) and math.isnan(x)) else (x, y)


@dataclass
class DryRunReport:
    """What a plan would do.

    Attributes
    ----------
    moves : list of (x_mm, y_mm, settle_s)
    captures : int
    lights : list of bool
        Every SetLights, in order.
    problems : list of str
        Targets outside the limits or with the object in direct view (empty: safe to run).
    travel_mm : float
    seconds : float
        Estimated run time: motion (trapezoid, feed and acceleration), settle, frames.
    steps : list of dict or None
        Per move, the controller's targets per motor (``{"x": steps, "y": steps}``) when a controller was given.
    """

    moves: list
    captures: int
    lights: list
    problems: list
    travel_mm: float
    seconds: float
    steps: list = field(default_factory=list)

    def to_dict(self) -> dict:
        out = dict(self.__dict__)
        steps = out.pop("steps") or [None] * len(self.moves)
        out["moves"] = [{"x_mm": x, "y_mm": y, "settle_s": s, "steps": st} for (x, y, s), st in zip(self.moves, steps)]
        return out


def dry_run(plan: Plan, *, limits_mm=((0.0, 320.0), (0.0, 320.0)), start_mm=(0.0, 0.0), feed_mm_min: float = 3000.0,
            accel_mm_s2: float = 500.0, frame_s: float = 0.35, view=None, controller=None,
            max_commands: int = 1_000_000) -> DryRunReport:
    """List a plan's moves and check them before anything moves.

    Parameters
    ----------
    plan : generator
    limits_mm : ((xmin, xmax), (ymin, ymax))
    start_mm : (x, y)
        Where the gantry starts (travel is measured from here).
    feed_mm_min, accel_mm_s2 : float
        For the time estimate.
    frame_s : float
        Seconds per capture (DENALI's rig: ≈ 3 frames/s with histogram dumps).
    view : callable, optional
        ``view(x_mm, y_mm) -> message or None``: the direct-view check
        (e.g. :func:`view_problem` bound to a sensor and object).
    controller : callable, optional
        ``controller(x_mm, y_mm) -> {motor: steps}``: the gantry controller's targets of a move (a Telemetrix
        rig's steps); a UserError it raises is a problem.
    max_commands : int
        Stop an endless plan.

    Returns
    -------
    DryRunReport
    """
    (x0, x1), (y0, y1) = limits_mm
    moves, lights, problems, steps = [], [], [], []
    captures, step, travel, seconds = 0, 0, 0.0, 0.0
    here, target, settle = tuple(start_mm), None, 0.0
    v, a = feed_mm_min / 60.0, accel_mm_s2
    checked: dict = {}
    reply = None
    for _ in range(max_commands):
        try:
            cmd = plan.send(reply)
        except StopIteration:
            break
        reply = None
        if isinstance(cmd, Move):
            moves.append((cmd.x_mm, cmd.y_mm, cmd.settle_s))
            target, settle = (cmd.x_mm, cmd.y_mm), cmd.settle_s
            if not (x0 <= cmd.x_mm <= x1 and y0 <= cmd.y_mm <= y1):
                problems.append(f"move {len(moves)} to ({cmd.x_mm:.1f}, {cmd.y_mm:.1f}) mm is outside the limits "
                                f"x {x0:g}..{x1:g}, y {y0:g}..{y1:g} mm")
            elif view is not None:
                key = (round(cmd.x_mm, 1), round(cmd.y_mm, 1))
                if key not in checked:
                    checked[key] = view(cmd.x_mm, cmd.y_mm)
                if checked[key]:
                    problems.append(f"move {len(moves)}: {checked[key]}")
            if controller is not None:
                try:
                    steps.append(controller(cmd.x_mm, cmd.y_mm))
                except UserError as exc:
                    steps.append(None)
                    problems.append(f"move {len(moves)}: {exc}")
        elif isinstance(cmd, SetLights):
            lights.append(cmd.on)
        elif isinstance(cmd, Capture):
            if target is None:
                problems.append(f"capture {step} comes before any move")
                target = here
            if target != here:
                d = math.dist(here, target)
                travel += d
                seconds += 2 * math.sqrt(d / a) if d <= v * v / a else 2 * v / a + (d - v * v / a) / v
                seconds += settle
                here = target
            seconds += frame_s
            reply = CaptureResult(step, cmd.repeat, None, None, None, target, None, None, dry=True)
            step += 1
            captures += 1
        elif not isinstance(cmd, Checkpoint):
            problems.append(f"unknown command {cmd!r}")
    else:
        problems.append(f"the plan did not end within {max_commands} commands")
    return DryRunReport(moves, captures, lights, problems, travel, seconds, steps)
