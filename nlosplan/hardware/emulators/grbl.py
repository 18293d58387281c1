"""An emulated GRBL 1.1h gantry on a pty: the real firmware's line protocol, states and rules.

Checked against the real firmware (GRBL 1.1h built with grbl-sim, the
``real_firmware`` tests run the same scenarios on both). What it does as
GRBL 1.1h does:

- Every ``\\r`` and every ``\\n`` ends a line; every line, empty ones too, is
  answered ``ok`` or ``error:N`` (so ``\\r\\n`` gets two answers).
- Settings (``$N=v``) are validated as the firmware does
  (:func:`~nlosplan.hardware.grbl_protocol.setting_error`: ``error:10`` for
  soft limits without homing, ...); the defaults are GRBL's generic ones
  (``$20=0``, ``$22=0``, 250 steps/mm, 500 mm/min, 10 mm/s², 200 mm travel).
- ``$$``, ``$#``, ``$I``, ``$G``, ``$X``, ``$H``, G0/G1 (work coordinates:
  machine = work + G54..G59 + G92), G4, G10 L2/L20, G20/G21, G53, G54..G59,
  G90/G91, G92/G92.1, G94, M-codes accepted and ignored.
- Machine space ``[-max_travel, 0]`` (``[0, max_travel]`` only with build
  option ``Z`` and a negative homing direction); with ``$20=1`` a target
  outside it raises ``ALARM:2`` and then nothing but a soft reset is answered.
- Power-up (port open, an Arduino's DTR reset) with ``$22=1``: locked in
  Alarm; hard reset zeroes the machine position, a soft reset keeps it;
  reset during motion gives ``ALARM:3``.
- Status reports with ``WCO:`` on the first report after a reset or an offset
  change and every 10 (idle) or 30 (moving) reports, ``Ov:`` in between,
  ``Pn:`` for active input pins, ``Hold:1`` while decelerating, ``Hold:0`` held.
- Homing runs the stock cycles (Z first, then X and Y): an axis without a
  switch ends in ``ALARM:9``, a limit pin that reads active all the time in
  ``ALARM:8`` (as in grbl-sim, where every pin reads active).

Not emulated: jogging (``$J=``), check mode, ``$RST``, sleep, startup lines'
execution, hard limits (``$21``) from pins, arcs, probing; G4 is answered at
once (GRBL first waits for the motion to end). Motion runs on a
clock ``time_scale`` times faster than real time.
"""

from __future__ import annotations

import threading
import time

from nlosplan.hardware.emulators.faults import GantryFaults, garble
from nlosplan.hardware.emulators.grbl_gcode import GcodeMixin
from nlosplan.hardware.emulators.pty import PtyDevice
from nlosplan.hardware.grbl_protocol import setting_error

__all__ = ["BANNER", "DEFAULT_SETTINGS", "EmulatedGrbl"]

BANNER = "Grbl 1.1h ['$' for help]"
VERSION = "1.1h.20190830"
LOCK_MESSAGE = "[MSG:'$H'|'$X' to unlock]"
#: GRBL 1.1h's generic defaults (``defaults.h``, DEFAULTS_GENERIC).
DEFAULT_SETTINGS = {0: 10, 1: 25, 2: 0, 3: 0, 4: 0, 5: 0, 6: 0, 10: 1, 11: 0.010, 12: 0.002, 13: 0, 20: 0, 21: 0,
                    22: 0, 23: 0, 24: 25.0, 25: 500.0, 26: 250, 27: 1.0, 30: 1000, 31: 0, 32: 0, 100: 250.0,
                    101: 250.0, 102: 250.0, 110: 500.0, 111: 500.0, 112: 500.0, 120: 10.0, 121: 10.0, 122: 10.0,
                    130: 200.0, 131: 200.0, 132: 200.0}
_FLOAT_SETTINGS = {11, 12, 24, 25, 27} | set(range(100, 133))
LINE_BUFFER = 80


class EmulatedGrbl(GcodeMixin, PtyDevice):
    """GRBL 1.1h on a pty (use :attr:`port` as the gantry port).

    Parameters
    ----------
    time_scale : float
        Motion and homing run this many times faster than real time.
    settings : dict, optional
        ``$N`` values overriding :data:`DEFAULT_SETTINGS` (as stored in EEPROM; not validated).
    faults : GantryFaults, optional
    boot_s : float
        Delay between the port being opened and the banner (an Arduino's reset).
    reset_on_open : bool
        Opening the port resets the controller (an Arduino's DTR reset: banner,
        machine position zeroed, power-up alarm lock). False: it keeps running
        and says nothing (grbl-sim, or a board without the DTR reset).
    pins : str
        Input pins that read active all the time (``Pn:`` letters); limit pins
        among them (X, Y, Z) make homing fail with ALARM:8. grbl-sim: ``PXYZRHS``.
    switches : str
        Axes with a working limit switch for homing (others end in ALARM:9).
    options : str
        Build option letters ``$I`` lists (``Z``: HOMING_FORCE_SET_ORIGIN).
    coordinates : dict, optional
        Stored work offsets ``{1: (x, y, z), ...}`` (1 = G54).
    """

    def __init__(self, *, time_scale: float = 1.0, settings: dict | None = None, faults: GantryFaults | None = None,
                 boot_s: float = 0.05, reset_on_open: bool = True, pins: str = "", switches: str = "XYZ",
                 options: str = "V", coordinates: dict | None = None) -> None:
        super().__init__("gantry")
        self.time_scale = float(time_scale)
        self.settings = {**DEFAULT_SETTINGS, **(settings or {})}
        self.faults = faults or GantryFaults()
        self.boot_s, self.reset_on_open = boot_s, reset_on_open
        self.pins, self.switches, self.options = pins, switches.upper(), options
        self.coords = {n: [0.0, 0.0, 0.0] for n in range(1, 7)}
        for n, xyz in (coordinates or {}).items():
            self.coords[int(n)] = [float(v) for v in xyz]
        self._mlock = threading.RLock()
        self._line = bytearray()
        self._overflow = False
        self._pending: list[tuple[float, str]] = []   # (due time, text) delayed output
        self._boot_due: float | None = None
        self.lines: list[str] = []
        self.moves = 0
        self._status_n = 0
        self._alarm_done = False
        self.pos = [0.0, 0.0, 0.0]     # machine position, mm
        self._power_up()

    # ------------------------------------------------------------------ clock and position
    def _now(self) -> float:
        return time.monotonic() * self.time_scale

    def position(self) -> tuple[float, float]:
        """Current (x, y) work position (machine position minus the active work offset), mm (thread-safe)."""
        with self._mlock:
            self._advance(self._now())
            wco = self._wco()
            return self.pos[0] - wco[0], self.pos[1] - wco[1]

    def machine_position(self) -> tuple[float, float, float]:
        """Current machine position (x, y, z), mm."""
        with self._mlock:
            self._advance(self._now())
            return tuple(self.pos)

    # ------------------------------------------------------------------ resets
    def _power_up(self) -> None:
        """A hard reset (power-up, or the DTR reset on port open): position zeroed, power-up lock."""
        self.pos = [0.0, 0.0, 0.0]
        self.state = "Alarm" if int(self.settings[22]) else "Idle"
        self._soft_state()

    def _soft_state(self) -> None:
        """What a reset clears (GRBL's gc_init, plan_reset, the sys struct): not the position, not the settings."""
        self._init_gcode()
        self._seg = None
        self._seg_feed = None
        self._resume = None        # (target, feed) of the move a feed hold interrupted
        self._queue: list = []
        self._held = False
        self._halted = False       # after ALARM:1/2: nothing but a soft reset is answered
        self._halted_ok = False    # the line that raised the alarm is answered 'ok' after the reset
        self._homing = None
        self._deferred: list[str] = []
        self._wco_counter = 0
        self._ovr_counter = 0
        self._line = bytearray()
        self._overflow = False

    def _greet(self) -> None:
        self._say("")
        self._say(BANNER)
        if self.state == "Alarm":
            self._say(LOCK_MESSAGE)

    def _soft_reset(self) -> None:
        if self._halted:
            if self._halted_ok:
                self._say("ok")
        elif self._homing is not None:
            self._say("ALARM:6")
            self.state = "Alarm"
        elif self.state == "Run" or (self.state == "Hold" and self._seg is not None):
            if self._seg is not None:
                self.pos = list(self._seg.position(self._now()))
            self._say("ALARM:3")
            self.state = "Alarm"
        if self.state != "Alarm":
            self.state = "Idle"
        self._soft_state()
        self._greet()

    # ------------------------------------------------------------------ output
    def _say(self, text: str, delay: float = 0.0) -> None:
        if delay > 0:
            self._pending.append((time.monotonic() + delay, text))
        else:
            self.send(text + "\r\n")

    def _ok(self) -> None:
        self._say("ok", self.faults.slow_ok_s)

    def _error(self, code: int) -> None:
        self._say(f"error:{code}", self.faults.slow_ok_s)

    def _wco(self) -> tuple:
        c = self.coords[self.coord_select]
        return tuple(c[i] + self.g92[i] for i in range(3))

    def _status(self) -> str:
        self._status_n += 1
        now = self._now()
        x, y, z = self.pos
        speed = self._seg.speed(now) * 60.0 if self._seg is not None and self.state in ("Run", "Hold") else 0.0
        state = self.state
        if state == "Hold":
            state = "Hold:0" if self._held and self._seg is None else "Hold:1"
        wco = self._wco()
        if int(self.settings[10]) & 1:
            text = f"<{state}|MPos:{x:.3f},{y:.3f},{z:.3f}|FS:{speed:.0f},0"
        else:
            text = f"<{state}|WPos:{x - wco[0]:.3f},{y - wco[1]:.3f},{z - wco[2]:.3f}|FS:{speed:.0f},0"
        if self.pins:
            text += f"|Pn:{self.pins}"
        busy = self.state in ("Run", "Hold", "Home")
        if self._wco_counter > 0:      # the firmware's two report counters (report.c)
            self._wco_counter -= 1
        else:
            self._wco_counter = (30 if busy else 10) - 1
            if self._ovr_counter == 0:
                self._ovr_counter = 1
            text += f"|WCO:{wco[0]:.3f},{wco[1]:.3f},{wco[2]:.3f}"
        if self._ovr_counter > 0:
            self._ovr_counter -= 1
        else:
            self._ovr_counter = (20 if busy else 10) - 1
            text += "|Ov:100,100,100"
        text += ">"
        n = self.faults.garble_status_every
        if n and self._status_n % n == 0:
            import numpy as np

            text = garble(text, np.random.default_rng(self._status_n))
        return text

    # ------------------------------------------------------------------ pty hooks
    def on_open(self) -> None:
        if not self.reset_on_open:
            return
        with self._mlock:
            self._power_up()
            self.drop_output()
            self._pending.clear()
        self._boot_due = time.monotonic() + self.boot_s

    def power_cycle(self) -> None:
        """Switch the controller off and on (settings and work offsets kept, as in EEPROM).

        What it prints while booting is dropped, as if nobody was listening.
        """
        with self._mlock:
            self._power_up()
            self.drop_output()
            self._pending.clear()

    def tick(self, now: float) -> None:
        with self._mlock:
            self._advance(self._now())
            due = [t for t in self._pending if t[0] <= now]
            if due:
                self._pending = [t for t in self._pending if t[0] > now]
                for _, text in due:
                    self._say(text)
            if self._boot_due is not None and now >= self._boot_due:
                self._boot_due = None
                self._greet()

    def on_bytes(self, data: bytes) -> None:
        with self._mlock:
            if self._boot_due is not None:
                return            # still booting (or resetting itself): what arrives is lost
            self._advance(self._now())
            for b in data:
                if b == 0x18:
                    self._soft_reset()
                elif self._halted:
                    continue      # ALARM:1/2: only a soft reset is heard
                elif b == 0x3F:   # '?'
                    self._say(self._status())
                elif b == 0x21:   # '!'
                    self._feed_hold()
                elif b == 0x7E:   # '~'
                    self._cycle_start()
                elif b >= 0x80:   # jog cancel and overrides: nothing to do here
                    continue
                elif b in (0x0A, 0x0D):
                    line, over = self._line.decode("ascii", errors="replace"), self._overflow
                    self._line, self._overflow = bytearray(), False
                    if self._homing is not None:
                        self._deferred.append(None if over else line)
                    elif over:
                        self._error(11)
                    else:
                        self._execute(line)
                elif b > 0x20:    # GRBL drops spaces and control characters
                    if len(self._line) >= LINE_BUFFER - 1:
                        self._overflow = True
                    else:
                        self._line += bytes([b]).upper()

    # ------------------------------------------------------------------ $ commands
    def _execute(self, line: str) -> None:
        self.lines.append(line)
        if not line:
            return self._ok()
        if not line.startswith("$"):
            if self.state == "Alarm":
                return self._error(9)
            return self._gcode(line)
        cmd = line[1:]
        idle_or_alarm = self.state in ("Idle", "Alarm")
        if cmd == "":
            self._say("[HLP:$$ $# $G $I $N $x=val $Nx=line $J=line $SLP $C $X $H ~ ! ? ctrl-x]")
        elif cmd == "$":
            if self.state in ("Run", "Hold"):
                return self._error(8)
            for k in sorted(self.settings):
                v = self.settings[k]
                self._say(f"${k}={v:.3f}" if k in _FLOAT_SETTINGS else f"${k}={int(v)}")
        elif cmd == "G":
            self._say(self._parser_state())
        elif cmd == "X":
            if self.state == "Alarm":
                self._say("[MSG:Caution: Unlocked]")
                self.state = "Idle"
        elif cmd == "#":
            if not idle_or_alarm:
                return self._error(8)
            for n in range(1, 7):
                self._say(f"[G{53 + n}:{','.join(f'{v:.3f}' for v in self.coords[n])}]")
            for name in ("G28", "G30"):
                self._say(f"[{name}:0.000,0.000,0.000]")
            self._say(f"[G92:{','.join(f'{v:.3f}' for v in self.g92)}]")
            self._say("[TLO:0.000]")
            self._say("[PRB:0.000,0.000,0.000:0]")
        elif cmd == "I":
            if not idle_or_alarm:
                return self._error(8)
            self._say(f"[VER:{VERSION}:]")
            self._say(f"[OPT:{self.options},15,128]")
        elif cmd == "N":
            self._say("$N0=")
            self._say("$N1=")
        elif cmd == "H":
            if not idle_or_alarm:
                return self._error(8)
            if not int(self.settings[22]):
                return self._error(5)
            return self._start_homing()
        elif "=" in cmd and cmd[:1].isdigit():
            if not idle_or_alarm:
                return self._error(8)
            key, _, val = cmd.partition("=")
            try:
                number, value = int(key), float(val)
            except ValueError:
                return self._error(2)
            err = setting_error(self.settings, number, value, variable_spindle="V" in self.options)
            if err:
                return self._error(err)
            self.settings[number] = value if number in _FLOAT_SETTINGS else float(int(value))
            if number == 22 and not int(value):
                self.settings[20] = 0.0
            if number == 13:
                self._wco_counter = 0
        else:
            return self._error(3)
        return self._ok()
