"""An emulated TMF8828 on the ams Arduino firmware, on a pty: commands, modes and histogram streaming.

It answers the single-character commands as DENALI's firmware
(``tmf8828_app.cpp`` in the ams Arduino driver DENALI vendors:
``serialInput``) does, with the firmware's own text: after every command the
state line (``TMF8828 state=stopped``, ``TMF882x state=measure``, ...);
``h`` the help screen (also printed at start-up); ``e``/``E`` a firmware
download (`` DWNL``, the configuration line, the help, the device line), after
which the application starts in TMF8828 mode and long range with histogram
dumps off -- a TMF882x image refuses the 8x8 mode switch
(``#Err,mode switch to,1``) and stays a TMF882x; ``o`` toggles the mode and
prints nothing when the switch works, and on a disabled device (DENALI's
sequence sends ``o`` right after ``d``) the I2C timeout and
``#Err,mode switch to,0``; ``O`` toggles short/long range and, when the
device is stopped, applies it and prints the configuration line (``#Conf``,
which names no range: the answer cannot tell the range); ``z`` the
configuration line and ``Histogram is N``; ``c`` the next configuration;
``m``, ``s``, ``d`` only the state line; an unknown character
``#Err,Cmd <c>``. Lines end with ``\n``. While measuring it prints frames in
the firmware's format (``#Cal`` dumps, then ``#Raw`` dumps, then ``#Obj`` per
result, as the real recording shows; 8x8 as four results of two dumps each
with the fixed pixel map). The counts come from ``expected(zones, range)``
(the simulator at the emulated gantry's current position, see
:mod:`nlosplan.hardware.rig`) with Poisson noise from a seeded generator,
clipped to 24 bits. Channel 0 (the reference SPAD) carries a stand-in pulse
(2,000 counts peak at bin 8): the simulator does not model it.

Not emulated: the Uno's reset window when the port opens, register dumps
(``a``, ``l``), factory calibration data, configuration 2 of ``c`` (the
firmware reads past its two-entry tables: answered ``#Err,Config``), the
device's version numbers (reported as 0).
"""

from __future__ import annotations

import threading
import time
from typing import Callable

import numpy as np

from nlosplan.hardware.emulators.faults import SensorFaults, garble, truncate
from nlosplan.hardware.emulators.pty import PtyDevice
from nlosplan.hardware.tmf8828_protocol import MAX_COUNT, N_BINS, ZoneMode, dump_lines, frame_dumps, obj_line
from nlosplan.sensor_models.noise import CaptureNoise

__all__ = ["EmulatedTMF8828"]

HELP = ("TMF8828 Arduino Driver", "UART commands", "a ... dump registers", "c ... next configuration",
        "d ... disable device", "e ... enable device and download TMF8828 FW",
        "E ... enable device and download TMF8821 FW", "f ... do fact calib", "h ... help ", "i ... i2c addr. change",
        "l ... load fact calib", "m ... measure", "o ... toggle between TMF8828 and TMF882X",
        "O ... toggle between short range and long range accuracy modes", "p ... power down",
        "r ... restore fact calib from file", "s ... stop measure", "t ... next persistance set", "w ... wakeup",
        "x ... clock corr on/off", "z ... histogram", "+ ... log+", "- ... log-", "# ... reset")
#: (period ms, kilo-iterations, SPAD map) per [TMF8828 mode][configuration] (the firmware's config tables)
CONFIGS = {(False, 0): (16, 10000, 6), (False, 1): (8, 2500, 7), (True, 0): (132, 10, 15), (True, 1): (264, 2500, 15)}
PERSISTENCE = (0, 1, 3)
STATES = {0: "disabled", 1: "standby", 2: "stopped", 3: "measure", 4: "error"}
DISABLED, STANDBY, STOPPED, MEASURE = 0, 1, 2, 3
_REF = 2000.0 * np.exp(-0.5 * ((np.arange(N_BINS) - 8.0) / 1.5) ** 2)
C_MM_PER_PS = 0.299792458 / 2  # one-way distance per picosecond of round trip


class EmulatedTMF8828(PtyDevice):
    """TMF8828 firmware on a pty (use :attr:`port` as the LiDAR port).

    Parameters
    ----------
    expected : callable
        ``expected(zones: str, range: str) -> (mean counts (rows, cols, 128), bin width ps)``,
        called once per frame.
    frame_period_s : float
        Minimum seconds between frame starts (the real sensor: ~0.03 s
        ranging, ~0.3 s with histogram dumps over serial).
    seed : int
        Poisson noise seed.
    faults : SensorFaults, optional
    address : int
        I2C address printed in every line (65 = 0x41).
    boot_s : float
        Seconds from the port's opening to setupFn's help screen (the real board: after the Uno's bootloader). 0
        sends it at once, where a driver that opens the port with pyserial usually never sees it: pyserial
        empties the input buffer after it opens the port, so the screen is dropped when it comes first.
    """

    def __init__(self, expected: Callable, *, frame_period_s: float = 0.05, seed: int = 0,
                 faults: SensorFaults | None = None, address: int = 65, boot_s: float = 0.0) -> None:
        super().__init__("lidar")
        self.expected = expected
        self.frame_period_s = frame_period_s
        self.rng = np.random.default_rng(seed)
        self.faults = faults or SensorFaults()
        self._frng = np.random.default_rng(self.faults.seed)
        self.address = address
        self.boot_s = float(boot_s)
        self._flock = threading.Lock()
        self._firmware_reset()
        self.frames_sent = 0
        self.data_lines = 0
        self._next_frame = 0.0
        self._result = 0
        self._unplugged = False
        self._pending: list[tuple[float, list[str]]] = []
        self.commands: list[str] = []

    def _firmware_reset(self) -> None:
        """``setupFn``: the application state after power-up (device disabled, TMF8828 mode, long range)."""
        self.image = None            # firmware image downloaded to the device: "tmf8828", "tmf882x" or None
        self.powered = False         # the device's enable pin (tmf8828Enable / tmf8828Disable): I2C answers
        self.state = DISABLED
        self.driver_log_errors = True   # setupFn sets the driver's log level to ERROR; enable() to NONE
        self._app_reset()
        self.device_long_range = True   # what the device runs (the flag applies when stopped)

    def _app_reset(self) -> None:
        """``resetAppState``."""
        self.tmf8828_mode = True     # modeIsTmf8828: 8x8 (TMF8828) or 3x3/4x4 (TMF882x legacy mode)
        self.long_range = True       # isLongRangeMode (the flag)
        self.config = 0              # configNr
        self.persistence = 0
        self.clock_correction = 1
        self.dump_mode = 0           # dumpHistogramOn: 0 off, 1 raw, 2 cal, 3 both

    @property
    def measuring(self) -> bool:
        return self.state == MEASURE

    @property
    def enabled(self) -> bool:
        return self.state != DISABLED

    @property
    def short_range(self) -> bool:
        return not self.device_long_range

    @property
    def zones(self) -> ZoneMode:
        if self.tmf8828_mode:
            return ZoneMode.Z8X8
        return ZoneMode.Z4X4 if self.config == 1 else ZoneMode.Z3X3

    # ------------------------------------------------------------------ hooks
    def on_open(self) -> None:
        with self._flock:   # an Arduino Uno resets when its port opens; setupFn prints the help screen
            self._firmware_reset()
            self._pending.clear()
            if self.boot_s > 0:
                self._pending.append((time.monotonic() + self.boot_s, list(HELP)))
        self.drop_output()
        if self.boot_s <= 0:
            self.send("".join(f"{ln}\n" for ln in HELP))

    def on_bytes(self, data: bytes) -> None:
        for ch in data.decode("ascii", errors="replace"):
            if not 33 <= ord(ch) < 126:
                continue    # serialInput skips control characters, blanks and DEL (and '~')
            self.commands.append(ch)
            lines = self._command(ch)
            if lines:
                due = time.monotonic() + self.faults.slow_answer_s
                with self._flock:
                    self._pending.append((due, lines))

    def _state_line(self) -> str:
        return f"{'TMF8828' if self.tmf8828_mode else 'TMF882x'} state={STATES[self.state]}"

    def _configure(self) -> list[str]:
        """``configure``: the configuration line (or ``#Err,Config`` for a configuration past the tables)."""
        conf = CONFIGS.get((self.tmf8828_mode, self.config))
        if conf is None:
            return ["#Err,Config"]
        period, kiter, spad = conf
        return [f"#Conf,Period={period}ms,KIter={kiter} SPAD={spad} Pers={PERSISTENCE[self.persistence]}"]

    def _set_mode(self) -> list[str]:
        """``setMode``: switch the device to the flag's mode; a failed switch forces TMF882x mode."""
        if self.powered and (self.image == "tmf8828" or not self.tmf8828_mode):
            return []
        # a device that is off does not answer on I2C: the driver's register check times out (logged at level ERROR)
        out = ["#Err,timeout 2300 reg=0x8 exp=0x0 0xFF"] if not self.powered and self.driver_log_errors else []
        out.append(f"#Err,mode switch to,{int(self.tmf8828_mode)}")
        self.tmf8828_mode = False
        return out

    def _enable(self, image: str) -> list[str]:
        if self.state != DISABLED:
            return ["Driver 1.14 FW 0.0.0.0. Chip 0.0 Serial 0x0"]
        self.image, self.powered, self.driver_log_errors, self.device_long_range = image, True, False, True
        self._app_reset()            # resetAppState also sets the app's state to disabled until configured
        out = [" DWNL"] + self._set_mode() + self._configure()
        self.state = STOPPED
        return out + list(HELP) + ["Driver 1.14 FW 0.0.0.0. Chip 0.0 Serial 0x0"]

    def _command(self, ch: str) -> list[str]:
        """What the firmware prints for one command character (its state line last, except for ``q``)."""
        with self._flock:
            out: list[str] = []
            if ch == "h":
                out = list(HELP)
            elif ch == "c":
                if self.state == STOPPED:
                    self.config = (self.config + 1) % 3
                    out = self._configure()
            elif ch in "eE":
                out = self._enable("tmf8828" if ch == "e" else "tmf882x")
            elif ch == "d":
                self.state = DISABLED
                self.image, self.powered = None, False
            elif ch == "w":
                if self.state == STANDBY:
                    self.state = STOPPED
            elif ch == "p":
                if self.state in (MEASURE, STOPPED):
                    self.state = STANDBY
            elif ch == "o":
                self.tmf8828_mode = not self.tmf8828_mode
                out = self._set_mode()
            elif ch == "O":
                self.long_range = not self.long_range
                if self.state == STOPPED:
                    self.device_long_range = self.long_range
                    out = self._configure()
            elif ch == "m":
                if self.state == STOPPED:
                    self.state = MEASURE
                    self._next_frame = time.monotonic()
            elif ch == "s":
                if self.state in (MEASURE, STOPPED):
                    self.state = STOPPED
            elif ch == "f":
                if self.state == STOPPED:
                    out = ["Fact Cal"] + self._configure()
            elif ch == "r":
                if self.state == STOPPED:
                    out = ["Set fact cal"]
            elif ch == "z":
                if self.state == STOPPED:
                    self.dump_mode = (self.dump_mode + 1) % 4
                    out = self._configure() + [f"Histogram is {self.dump_mode}"]
            elif ch == "x":
                self.clock_correction = 1 - self.clock_correction
                out = [f"Clk corr is {self.clock_correction}"]
            elif ch == "i":
                out = [f"I2C Addr={self.address}"]
            elif ch == "t":
                if self.state == STOPPED:
                    self.persistence = (self.persistence + 1) % 3
                    out = self._configure()
            elif ch in "+-":
                out = ["Log=0"]
            elif ch == "#":
                if self.state != DISABLED:
                    self.state = STOPPED
                    out = ["Reset TMF8828"] + self._set_mode()
            elif ch == "q":
                return []          # serialInput returns before its state line
            elif ch in "al":
                out = []           # register dumps: not emulated
            else:
                out = [f"#Err,Cmd {ch}"]
            return out + [self._state_line()]

    def tick(self, now: float) -> None:
        with self._flock:
            due = [t for t in self._pending if t[0] <= now]
            if due:
                self._pending = [t for t in self._pending if t[0] > now]
            measuring = self.measuring
        for _, lines in due:
            self.send("".join(f"{ln}\n" for ln in lines))
        if not measuring or now < self._next_frame or self.queued():
            return
        self._next_frame = now + self.frame_period_s
        self._emit_frame()

    # ------------------------------------------------------------------ frames
    def _emit_frame(self) -> None:
        zones = self.zones
        mean, bin_ps = self.expected(zones.value, "short" if self.short_range else "long")
        counts = CaptureNoise(MAX_COUNT).draw(self.rng, mean)  # the sensor's noise model: Poisson, 24-bit clip
        ref = CaptureNoise().draw(self.rng, _REF)
        dumps = frame_dumps(counts, zones, ref)
        peak = np.argmax(counts.reshape(-1, N_BINS), axis=1)
        flat_dist = np.rint((peak + 0.5) * bin_ps * C_MM_PER_PS).astype(np.int64)
        lines: list[str] = []
        per, nres = zones.dumps_per_result, zones.results_per_frame
        self._result = -(-self._result // nres) * nres % 256  # sub-capture k has result_number % 4 == k
        for r in range(zones.results_per_frame):
            result = dumps[r * per:(r + 1) * per]
            if self.dump_mode in (2, 3):      # the result's calibration dumps, then its raw ones (the recording)
                for d in result:
                    cal = np.zeros_like(d)
                    cal[0] = ref
                    lines += dump_lines(cal, "Cal", self.address)
            if self.dump_mode in (1, 3):
                for d in result:
                    lines += dump_lines(d, "Raw", self.address)
            dist = np.zeros(36, np.int64)
            conf = np.zeros(36, np.int64)
            k = min(18, flat_dist.size)
            dist[:k], conf[:k] = flat_dist[:k], 100
            lines.append(obj_line(self._result, address=self.address, systick=int(time.monotonic() * 1e6) % 2**32,
                                  distances_mm=dist, confidences=conf))
            self._result = (self._result + 1) % 256
        self.send("".join(f"{ln}\n" for ln in self._faulty(lines)))
        self.frames_sent += 1
        n = self.faults.disconnect_after_frames
        if n and self.frames_sent == n and not self._unplugged:
            self._unplugged = True
            self.disconnect(self.faults.down_s)

    def _faulty(self, lines: list[str]) -> list[str]:
        f = self.faults
        if not (f.garble_every or f.truncate_every or f.drop_every):
            self.data_lines += len(lines)
            return lines
        out = []
        for ln in lines:
            self.data_lines += 1
            k = self.data_lines
            if f.drop_every and k % f.drop_every == 0:
                continue
            if f.garble_every and k % f.garble_every == 0:
                ln = garble(ln, self._frng)
            if f.truncate_every and k % f.truncate_every == 0:
                ln = truncate(ln, self._frng)
            out.append(ln)
        return out
