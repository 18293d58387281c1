"""A rig: the sensor, gantry and lights drivers and their configuration, real or emulated.

:func:`open_rig` opens the real devices; :func:`emulated_rig` starts both pty
emulators backed by the fast simulator (the DENALI scene with the object at
the emulated gantry's current position, any (x, y) within the limits) and
opens the *same* drivers on their ptys (STYLE.md 6, 7: one seeded factory for
the whole bench).
"""

from __future__ import annotations

import threading
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Iterator

from nlosplan.errors import UserError

__all__ = ["Rig", "emulated_rig", "open_rig", "sensor_preset"]


@dataclass
class Rig:
    """Drivers and settings of one capture rig.

    Attributes
    ----------
    sensor : TMF8828
    gantry : Grbl
    lights : object with ``state`` and ``set(on)``
    sensor_config : SensorConfig
        The sensor model the captures are stored with.
    geometry : {"denali", None}
        Whether gantry mm map onto the DENALI scene (labels x, y; direct-view checks).
    feed_mm_min : float
    park_mm : (x, y) or None
        Where finalize parks the gantry (None: leave it).
    emulated : bool
    emulators : tuple
        The emulator objects (empty for real hardware).
    """

    sensor: object
    gantry: object
    lights: object
    sensor_config: object
    geometry: str | None = "denali"
    feed_mm_min: float = 3000.0
    park_mm: tuple | None = (0.0, 0.0)
    emulated: bool = False
    emulators: tuple = ()

    def close(self) -> None:
        """Close the drivers (the sensor is stopped first)."""
        for dev in (self.sensor, self.gantry):
            try:
                dev.close()
            except Exception:  # noqa: BLE001 - closing must reach every device
                pass


def sensor_preset(zones: str, range_mode: str):
    """The sensor model of a TMF8828 mode (``tmf8828-<zones>-<range>``)."""
    from nlosplan.sensor_models import preset
    from nlosplan.sensor_models.presets import PRESET_NAMES

    name = f"tmf8828-{zones}-{range_mode}"
    if name not in PRESET_NAMES:
        have = ", ".join(n[8:] for n in PRESET_NAMES if n.startswith("tmf8828-"))
        raise UserError(f"no sensor model for TMF8828 {zones} {range_mode} range (presets: {have}); "
                        "give one with --sensor FILE")
    return preset(name)


def _prepare_gantry(gantry, *, home: bool, unlock: bool) -> None:
    gantry.connect()
    if gantry.alarm is not None:
        if home:
            gantry.home()
        elif unlock:
            gantry.unlock()
        else:
            raise UserError(f"the gantry on {gantry.port_name} is locked in alarm; pass --home (run $H) or "
                            "--unlock (send $X, only if you know where it is)")
    elif home:
        gantry.home()


def open_rig(lidar, gantry, *, zones: str = "3x3", range_mode: str = "short", baudrate: int = 2_000_000,
             sensor_config=None, limits_mm=((0.0, 320.0), (0.0, 320.0)), feed_mm_min: float = 3000.0,
             lights=None, home: bool = False, unlock: bool = False, park_mm=(0.0, 0.0),
             geometry: str | None = "denali") -> Rig:
    """Open the real rig: TMF8828 on ``lidar``, GRBL on ``gantry``; start measuring.

    Raises
    ------
    UserError
        A port cannot be opened, the gantry is locked and neither ``home`` nor ``unlock`` was given.
    """
    from nlosplan.hardware.grbl import Grbl
    from nlosplan.hardware.lights import ManualLights
    from nlosplan.hardware.tmf8828 import TMF8828

    cfg = sensor_config or sensor_preset(zones, range_mode)
    sensor = TMF8828(lidar, baudrate=baudrate)
    try:
        g = Grbl(gantry, limits_mm=limits_mm, feed_mm_min=feed_mm_min)
    except BaseException:
        sensor.close()
        raise
    rig = Rig(sensor, g, lights or ManualLights(), cfg, geometry, feed_mm_min, park_mm)
    try:
        _prepare_gantry(g, home=home, unlock=unlock)
        sensor.start(zones, range_mode)
    except BaseException:
        rig.close()
        raise
    return rig


class SceneHistograms:
    """Expected histograms of the DENALI scene at the emulated gantry's position (cached per 0.1 mm).

    Parameters
    ----------
    obj, size : str
    position : callable
        ``position() -> (x_mm, y_mm)`` of the gantry.
    lights : EmulatedLights
    fidelity : str
        Fast-simulator fidelity (``draft`` ≈ 40 ms per new position after compiling).
    """

    def __init__(self, obj: str, size: str, position, lights, fidelity: str = "draft", cache: int = 256) -> None:
        self.obj, self.size, self.position, self.lights, self.fidelity = obj, size, position, lights, fidelity
        self._cache: dict = {}
        self._max = cache
        self._lock = threading.Lock()
        self.computed = 0

    def __call__(self, zones: str, range_mode: str):
        from nlosplan.simulators import scene_at
        from nlosplan.simulators import expected_histogram

        sensor = sensor_preset(zones, range_mode)
        x, y = self.position()
        lights = "on" if self.lights.state else "off"
        key = (zones, range_mode, round(x, 1), round(y, 1), lights)
        with self._lock:
            hit = self._cache.get(key)
        if hit is None:
            import warnings

            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                hit = expected_histogram(scene_at(self.obj, self.size, x, y, lights), sensor, fidelity=self.fidelity)
            self.computed += 1
            with self._lock:
                if len(self._cache) >= self._max:
                    self._cache.pop(next(iter(self._cache)))
                self._cache[key] = hit
        return hit, sensor.bin_width_ps


@contextmanager
def emulated_rig(*, obj: str = "A", size: str = "8in", zones: str = "3x3", range_mode: str = "short",
                 lights: bool = False, fidelity: str = "draft", seed: int = 0, time_scale: float = 20.0,
                 frame_period_s: float = 0.02, sensor_faults=None, gantry_faults=None,
                 limits_mm=((0.0, 320.0), (0.0, 320.0)), feed_mm_min: float = 3000.0, park_mm=(0.0, 0.0),
                 quiet_s: float = 0.05, frame_timeout: float = 5.0, gantry_settings: dict | None = None,
                 home: bool = False, unlock: bool = False, sensor_config=None) -> Iterator[Rig]:
    """Both emulators on ptys, the production drivers opened on them, measuring.

    Parameters
    ----------
    obj, size, lights
        The DENALI scene of the emulated sensor (lights: initial state).
    zones, range_mode : str
        TMF8828 mode (a ``tmf8828-<zones>-<range>`` preset must exist).
    fidelity : str
        Simulator fidelity of the emulated histograms.
    seed : int
        Poisson noise seed.
    time_scale : float
        Emulated motion runs this much faster than real time.
    frame_period_s : float
        Emulated frame period.
    sensor_faults, gantry_faults : SensorFaults, GantryFaults, optional
    gantry_settings : dict, optional
        GRBL ``$N`` overrides (e.g. ``{22: 1}`` to need homing).
    sensor_config : SensorConfig, optional
        The model stored with the captures (default: the mode's preset, which
        also makes the emulated histograms).

    Yields
    ------
    Rig
        With ``emulated=True`` and ``emulators=(lidar emulator, gantry emulator)``.
    """
    from nlosplan.hardware.emulators import EmulatedGrbl, EmulatedTMF8828
    from nlosplan.hardware.grbl import Grbl
    from nlosplan.hardware.lights import EmulatedLights
    from nlosplan.hardware.tmf8828 import TMF8828

    cfg = sensor_config or sensor_preset(zones, range_mode)
    (x0, x1), (y0, y1) = limits_mm
    settings = {130: x1, 131: y1, **(gantry_settings or {})}
    light = EmulatedLights(lights)
    g_emu = EmulatedGrbl(time_scale=time_scale, settings=settings, faults=gantry_faults).start()
    hist = SceneHistograms(obj, size, g_emu.position, light, fidelity)
    hist(zones, range_mode)  # compile the simulator before the sensor streams
    s_emu = EmulatedTMF8828(hist, frame_period_s=frame_period_s, seed=seed, faults=sensor_faults).start()
    rig = None
    try:
        sensor = TMF8828(s_emu.port, quiet_s=quiet_s, frame_timeout=frame_timeout)
        gantry = Grbl(g_emu.port, limits_mm=limits_mm, feed_mm_min=feed_mm_min, poll_s=0.01)
        rig = Rig(sensor, gantry, light, cfg, "denali", feed_mm_min, park_mm, True, (s_emu, g_emu))
        _prepare_gantry(gantry, home=home, unlock=unlock)
        sensor.start(zones, range_mode)
        yield rig
    finally:
        if rig is not None:
            rig.close()
        s_emu.close()
        g_emu.close()
