"""A rig: the sensor, gantry and lights drivers and their configuration, each device real or emulated.

:func:`rig_session` opens the rig: the gantry first (GRBL, Telemetrix, or
``auto``: whichever answers; prepared by the firmware's rules), then the
sensor (started in its mode). Either device may be a pty emulator instead
(``emulate={"lidar"}``, ``{"gantry"}`` or both): the emulated TMF8828
streams histograms of the DENALI scene from the fast simulator with the
object wherever the gantry is (the emulated gantry's position, or the real
gantry's last reported one), and the *same* drivers open the emulators'
ptys (STYLE.md 6, 7: one seeded factory for the whole bench).
:func:`emulated_rig` is the all-emulated bench; :func:`open_rig` the real one.
"""

from __future__ import annotations

import threading
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Iterator

from nlosplan.errors import UserError

__all__ = ["DEVICES", "Rig", "RigOptions", "device_errors", "emulated_rig", "open_gantry", "open_rig", "park_target",
           "rig_session",
           "sensor_preset"]

DEVICES = ("lidar", "gantry")
#: Settings of the emulated GRBL gantry beyond GRBL's defaults (a belt gantry: 100 mm/s, 500 mm/s²).
EMULATED_GRBL = {110: 6000.0, 111: 6000.0, 120: 500.0, 121: 500.0}


@dataclass
class Rig:
    """Drivers and settings of one capture rig.

    Attributes
    ----------
    sensor : TMF8828
    gantry : Grbl or TelemetrixGantry
    lights : object with ``state`` and ``set(on)``
    sensor_config : SensorConfig
        The sensor model the captures are stored with.
    geometry : {"denali", None}
        Whether gantry mm map onto the DENALI scene (labels x, y; direct-view checks).
    feed_mm_min : float
    park_mm : (x, y) or None
        Where finalize parks the gantry (None: leave it).
    emulated : tuple of str
        The emulated devices (``"lidar"``, ``"gantry"``); empty for a real rig.
    emulators : tuple
        The emulator objects.
    """

    sensor: object
    gantry: object
    lights: object
    sensor_config: object
    geometry: str | None = "denali"
    feed_mm_min: float = 3000.0
    park_mm: tuple | None = (0.0, 0.0)
    emulated: tuple = ()
    emulators: tuple = ()

    def close(self) -> None:
        """Close the drivers (the sensor is stopped first)."""
        for dev in (self.sensor, self.gantry):
            try:
                if dev is not None:
                    dev.close()
            except Exception:  # noqa: BLE001 - closing must reach every device
                pass


def device_errors() -> tuple[type, ...]:
    """The exceptions by which a device (not the user's input) ends an open or a run."""
    from nlosplan.hardware.grbl_frame import FrameChanged
    from nlosplan.hardware.grbl_protocol import GrblAlarm, GrblError
    from nlosplan.hardware.telemetrix import TelemetrixError
    from nlosplan.hardware.tmf8828 import SensorError
    from nlosplan.hardware.transport import ConnectionLost, DeviceTimeout

    return GrblAlarm, GrblError, FrameChanged, TelemetrixError, SensorError, ConnectionLost, DeviceTimeout


def sensor_preset(zones: str, range_mode: str):
    """The sensor model of a TMF8828 mode: DENALI's unit as calibrated on its real Table 2 for the short range it
    captured in (``denali-tmf8828-<zones>``), else the datasheet's ``tmf8828-<zones>-<range>``."""
    from nlosplan.sensor_models import preset
    from nlosplan.sensor_models.presets import PRESET_NAMES

    name = f"denali-tmf8828-{zones}" if range_mode == "short" else ""
    if name in PRESET_NAMES:
        return preset(name)
    name = f"tmf8828-{zones}-{range_mode}"
    if name not in PRESET_NAMES:
        have = ", ".join(n[8:] for n in PRESET_NAMES if n.startswith("tmf8828-"))
        raise UserError(f"no sensor model for TMF8828 {zones} {range_mode} range (presets: {have}); "
                        "give one with --sensor FILE")
    return preset(name)


def detect_gantry_kind(port) -> str:
    """``grbl`` or ``telemetrix``: which firmware answers on ``port``, confusing neither.

    The probe (:func:`~nlosplan.hardware.gantry.probe_firmware`) sends nothing while the board boots after
    the port opened (:data:`~nlosplan.hardware.gantry.BOOT_WAIT_S`, the telemetrix client's wait; a GRBL
    banner ends it early), then Telemetrix's version request (GRBL ignores it) every 0.5 s, and GRBL's ``?``
    only a second later, when a Telemetrix board would have answered; a soft reset after 2.5 s more.

    Raises
    ------
    UserError
        Neither answers (one line: nothing, or what arrived).
    """
    from nlosplan.hardware.gantry import BOOT_WAIT_S, probe_firmware
    from nlosplan.hardware.transport import open_serial

    ser, owned = open_serial(port, 115200)
    try:
        found = probe_firmware(ser, timeout=BOOT_WAIT_S + 4.0, quiet_s=BOOT_WAIT_S, query_every_s=0.5,
                               grbl_after_s=BOOT_WAIT_S + 1.0, reset_after_s=BOOT_WAIT_S + 2.5, poll_s=0.25)
    finally:
        if owned:
            ser.close()
    if found.kind is None:
        raise UserError(f"--gantry-kind auto: neither GRBL nor Telemetrix4Arduino answers on {port} "
                        f"(got {found.describe_seen()}): wrong port, controller off, or another firmware")
    return found.kind


def open_gantry(kind: str, port, *, limits_mm=((0.0, 320.0), (0.0, 320.0)), feed_mm_min: float = 3000.0,
                work_offset="auto", telemetrix=None, home: bool = False, unlock: bool = False, poll_s: float = 0.05):
    """Open and prepare a gantry driver of ``kind`` (``grbl``, ``telemetrix`` or ``auto``) on ``port``.

    Raises
    ------
    UserError
        Locked in alarm without ``home``/``unlock``, limits outside the machine space, wrong firmware, ...
    GrblAlarm, GrblError, TelemetrixError, DeviceTimeout, ConnectionLost
        The device failed (the caller turns these into one line).
    """
    from nlosplan.hardware.grbl import Grbl
    from nlosplan.hardware.telemetrix import TelemetrixGantry

    if kind == "auto":
        kind = detect_gantry_kind(port)
    if kind == "grbl":
        if telemetrix is not None:
            raise UserError("--rig-file describes a Telemetrix gantry; this one is GRBL (drop --rig-file)")
        g = Grbl(port, limits_mm=limits_mm, feed_mm_min=feed_mm_min, work_offset=work_offset, poll_s=poll_s)
    elif kind == "telemetrix":
        if work_offset != "auto":
            raise UserError("--work-offset is GRBL's; a Telemetrix gantry's origin is origin_mm in its --rig-file")
        g = TelemetrixGantry(port, config=telemetrix, limits_mm=limits_mm, feed_mm_min=feed_mm_min)
    else:
        raise UserError(f"gantry kind {kind!r}; allowed: grbl, telemetrix, auto")
    try:
        g.prepare(home=home, unlock=unlock)
    except BaseException:
        g.close()
        raise
    return g


class SceneHistograms:
    """Expected histograms of the DENALI scene at the gantry's position (cached per 0.1 mm).

    Parameters
    ----------
    obj, size : str
    position : callable
        ``position() -> (x_mm, y_mm)`` of the gantry in the user frame.
    lights : EmulatedLights
    fidelity : str
        Fast-simulator fidelity (``draft`` ≈ 0.2 s per new position after compiling).
    limits_mm : ((x0, x1), (y0, y1)), optional
        The gantry's travel. Each position is simulated in one batch with the scene at the four corners of
        the travel, so that every position shares one compiled simulator: alone, a position's scene pads its
        near-wall and time-grid blocks to its own sizes, and crossing a size recompiled (~5 s on 2 cores, a
        frame the driver waited for in vain, then a reconnect).
    """

    def __init__(self, obj: str, size: str, position, lights, fidelity: str = "draft", cache: int = 256,
                 limits_mm=None) -> None:
        self.obj, self.size, self.position, self.lights, self.fidelity = obj, size, position, lights, fidelity
        self.limits_mm = limits_mm
        self._cache: dict = {}
        self._anchors: dict = {}
        self._max = cache
        self._lock = threading.Lock()
        self.computed = 0

    def _scene(self, x: float, y: float, lights: str, sensor):
        import warnings

        from nlosplan.simulators import scene_at
        from nlosplan.simulators.presets.scene_model import scene_model, scene_options

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return scene_at(self.obj, self.size, x, y, lights, **scene_options(scene_model(sensor)))

    def __call__(self, zones: str, range_mode: str):
        import numpy as np

        from nlosplan.simulators import expected_batch

        sensor = sensor_preset(zones, range_mode)
        x, y = self.position()
        lights = "on" if self.lights.state else "off"
        key = (zones, range_mode, round(x, 1), round(y, 1), lights)
        with self._lock:
            hit = self._cache.get(key)
        if hit is None:
            anchors = []
            if self.limits_mm is not None:
                akey = (zones, range_mode, lights)
                if akey not in self._anchors:
                    (x0, x1), (y0, y1) = self.limits_mm
                    self._anchors[akey] = [self._scene(ax, ay, lights, sensor) for ax in (x0, x1) for ay in (y0, y1)]
                anchors = self._anchors[akey]
            scenes = [self._scene(x, y, lights, sensor), *anchors]
            hit = np.asarray(expected_batch(scenes, sensor, fidelity=self.fidelity).expected)[0]
            self.computed += 1
            with self._lock:
                if len(self._cache) >= self._max:
                    self._cache.pop(next(iter(self._cache)))
                self._cache[key] = hit
        return hit, sensor.bin_width_ps


def _gantry_emulator(kind: str, *, time_scale: float, limits_mm, faults, settings, telemetrix):
    """The emulator of a gantry kind and a position function in the user frame."""
    from nlosplan.hardware.emulators import EmulatedGrbl, EmulatedTelemetrix
    from nlosplan.hardware.telemetrix_config import TelemetrixConfig

    if kind == "grbl":
        (x0, x1), (y0, y1) = limits_mm
        emu = EmulatedGrbl(time_scale=time_scale, faults=faults,
                           settings={**EMULATED_GRBL, 130: x1 - x0, 131: y1 - y0, **(settings or {})})
        return emu, emu.position
    if kind == "telemetrix":
        if faults is not None and any(getattr(faults, k) for k in faults.__dataclass_fields__):
            raise UserError("the emulated Telemetrix gantry takes no faults (they are GRBL's: alarm, slow-ok)")
        cfg = telemetrix or TelemetrixConfig()
        emu = EmulatedTelemetrix(time_scale=time_scale)
        return emu, lambda: cfg.to_mm(*emu.carriage_steps())   # where the carriage is, whatever the counters say
    raise UserError(f"an emulated gantry is grbl or telemetrix, not {kind!r} (auto probes a real port)")


@dataclass(frozen=True)
class RigOptions:
    """How :func:`rig_session` opens the rig: the devices, the sensor's mode, the motion, the emulators.

    Parameters
    ----------
    lidar, gantry : str or serial object, optional
        Ports of the real devices (not for emulated ones).
    emulate : iterable of {"lidar", "gantry"}
    gantry_kind : {"grbl", "telemetrix", "auto"}
    telemetrix : TelemetrixConfig, optional
        The Telemetrix rig file (default: DENALI's).
    work_offset : "auto", "keep" or (x, y)
        GRBL only (:mod:`~nlosplan.hardware.grbl_frame`).
    baudrate : int
        The real sensor's.
    zones, range_mode, sensor_config
        The sensor's mode, and its model (default: the preset of the mode).
    limits_mm, feed_mm_min, home, unlock, park_mm, geometry
        The motion: limits, feed, GRBL homing and unlock, where to park at the end, the rig's geometry.
    lights : lights object, optional
        For a real sensor (default: ask a person); an emulated sensor has emulated lights (``lights_on``).
    obj, size, fidelity, seed, frame_period_s, sensor_faults, quiet_s, frame_timeout
        The emulated sensor.
    time_scale, gantry_faults, gantry_settings
        The emulated gantry (``gantry_settings``: GRBL ``$N`` values).
    """

    lidar: object = None
    gantry: object = None
    emulate: tuple = DEVICES
    gantry_kind: str = "grbl"
    telemetrix: object = None
    work_offset: object = "auto"
    baudrate: int = 2_000_000
    zones: str = "3x3"
    range_mode: str = "short"
    sensor_config: object = None
    limits_mm: tuple = ((0.0, 320.0), (0.0, 320.0))
    feed_mm_min: float = 3000.0
    home: bool = False
    unlock: bool = False
    park_mm: object = (0.0, 0.0)
    geometry: str | None = "denali"
    lights: object = None
    lights_on: bool = False
    obj: str = "A"
    size: str = "8in"
    fidelity: str = "draft"
    seed: int = 0
    frame_period_s: float = 0.02
    sensor_faults: object = None
    quiet_s: float = 0.05
    frame_timeout: float = 5.0
    time_scale: float = 20.0
    gantry_faults: object = None
    gantry_settings: dict | None = None


@contextmanager
def rig_session(options: RigOptions) -> Iterator[Rig]:
    """Open the rig (gantry, then sensor), each device on its port or on a pty emulator; close it at the end.

    Parameters
    ----------
    options : RigOptions

    Yields
    ------
    Rig

    Raises
    ------
    UserError
        A port is given for an emulated device or missing for a real one, and what the drivers raise.
    """
    from nlosplan.hardware.emulators import EmulatedTMF8828
    from nlosplan.hardware.lights import EmulatedLights, ManualLights
    from nlosplan.hardware.tmf8828 import TMF8828

    o = options
    emulate = tuple(d for d in DEVICES if d in set(o.emulate))
    for name, port in (("lidar", o.lidar), ("gantry", o.gantry)):
        if name in emulate and port is not None:
            raise UserError(f"--{name} {port} and an emulated {name} name the same device: drop one")
        if name not in emulate and port is None:
            raise UserError(f"give --{name} PORT for the real {name}, or emulate it")
    cfg = o.sensor_config or sensor_preset(o.zones, o.range_mode)
    emulators, sensor, g = [], None, None
    try:
        if "gantry" in emulate:
            g_emu, position = _gantry_emulator(o.gantry_kind, time_scale=o.time_scale, limits_mm=o.limits_mm,
                                               faults=o.gantry_faults, settings=o.gantry_settings,
                                               telemetrix=o.telemetrix)
            emulators.append(g_emu.start())
            g = open_gantry(o.gantry_kind, g_emu.port, limits_mm=o.limits_mm, feed_mm_min=o.feed_mm_min,
                            work_offset=o.work_offset, telemetrix=o.telemetrix, home=o.home, unlock=o.unlock,
                            poll_s=0.01)
        else:
            g = open_gantry(o.gantry_kind, o.gantry, limits_mm=o.limits_mm, feed_mm_min=o.feed_mm_min,
                            work_offset=o.work_offset, telemetrix=o.telemetrix, home=o.home, unlock=o.unlock)

            def position():
                return g.last_xy or (o.limits_mm[0][0], o.limits_mm[1][0])
        if "lidar" in emulate:
            light = EmulatedLights(o.lights_on)
            hist = SceneHistograms(o.obj, o.size, position, light, o.fidelity, limits_mm=o.limits_mm)
            hist(o.zones, o.range_mode)  # compile the simulator before the sensor streams
            s_emu = EmulatedTMF8828(hist, frame_period_s=o.frame_period_s, seed=o.seed, faults=o.sensor_faults).start()
            emulators.append(s_emu)
            sensor = TMF8828(s_emu.port, quiet_s=o.quiet_s, frame_timeout=o.frame_timeout)
        else:
            light = o.lights or ManualLights()
            sensor = TMF8828(o.lidar, baudrate=o.baudrate)
        rig = Rig(sensor, g, light, cfg, o.geometry, o.feed_mm_min, park_target(g, o.park_mm), emulate,
                  tuple(emulators))
        sensor.start(o.zones, o.range_mode)
        yield rig
    finally:
        for dev in (sensor, g):
            if dev is not None:
                try:
                    dev.close()
                except Exception:  # noqa: BLE001 - closing must reach every device
                    pass
        for emu in emulators:
            emu.close()


def park_target(gantry, park_mm):
    """Where to park: on a gantry whose counters restart where the carriage stands when the port opens
    (Telemetrix, GRBL without homing), its origin when that lies inside the limits -- so the next session
    counts from the same place -- else ``park_mm`` (None: do not park)."""
    if park_mm is None or getattr(gantry, "referenced", True):
        return park_mm
    ox, oy = gantry.origin_xy()
    (x0, x1), (y0, y1) = gantry.limits_mm
    return (ox, oy) if x0 <= ox <= x1 and y0 <= oy <= y1 else park_mm


def emulated_rig(**kw) -> Iterator[Rig]:
    """Both devices emulated (:func:`rig_session` with ``emulate=("lidar", "gantry")``); a context manager.

    ``lights`` (bool) is the emulated lights' initial state.
    """
    if "lights" in kw:
        kw["lights_on"] = bool(kw.pop("lights"))
    return rig_session(RigOptions(emulate=DEVICES, **kw))


def open_rig(lidar, gantry, **kw) -> Iterator[Rig]:
    """Both devices real (:func:`rig_session` with ``emulate=()``); a context manager."""
    return rig_session(RigOptions(lidar=lidar, gantry=gantry, emulate=(), **kw))
