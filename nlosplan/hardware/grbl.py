"""GRBL 1.1 gantry driver over pyserial (an XY gantry on a CNC shield), by the real firmware's rules.

Send-and-wait (every line waits for its ``ok``) for commands, character
counting (GRBL's 128-byte receive buffer) for :meth:`Grbl.stream`, ``?``
status polling to wait for Idle, ``ALARM:``/``error:`` raised as
:class:`GrblAlarm`/:class:`GrblError`. :meth:`Grbl.prepare` finds GRBL on
the port (:func:`~nlosplan.hardware.gantry.probe_firmware`), reads ``$$``,
``$I`` and ``$#``, clears an alarm only when asked (soft reset first after
ALARM:1/2, as GRBL requires; then ``$H`` or ``$X``), and sets and checks
the work offset that makes the plan's coordinates GRBL's work coordinates
(:mod:`~nlosplan.hardware.grbl_frame`). Positions come back in that user
frame, with the raw machine position for audit.

Examples
--------
>>> with Grbl("/dev/ttyUSB0", limits_mm=((0, 320), (0, 320))) as gantry:   # doctest: +SKIP
...     gantry.prepare(home=True)
...     gantry.move_to(35.556, 0.0, feed_mm_min=3000).xy_mm   # waits for Idle
(35.556, 0.0)
"""

from __future__ import annotations

import math
import time

from nlosplan.errors import UserError
from nlosplan.hardware.gantry import GantryPosition, LimitError, WrongFirmware, check_box, probe_firmware
from nlosplan.hardware.grbl_frame import TOL_MM, FrameChanged, WorkFrame, parse_work_offset, plan_frame
from nlosplan.hardware.grbl_homing import homing_diagnosis
from nlosplan.hardware.grbl_link import RX_BUFFER, GrblLink
from nlosplan.hardware.grbl_protocol import (CRITICAL_ALARMS, GrblAlarm, GrblError, Status, parse_build_info,
                                             parse_ngc_parameters, parse_settings)
from nlosplan.hardware.transport import DeviceTimeout

__all__ = ["RX_BUFFER", "Grbl", "GrblAlarm", "GrblError", "LimitError", "Status"]


class Grbl(GrblLink):
    """A GRBL 1.1 controller driving the gantry in the user frame.

    Parameters
    ----------
    port : str or serial object
    baudrate : int
        115200 for GRBL 1.1.
    limits_mm : ((xmin, xmax), (ymin, ymax))
        Limits in the user frame, checked before every move (mm).
    feed_mm_min : float
        Default feed rate of moves (mm/min).
    work_offset : "auto", "keep" or (x, y)
        How the user frame maps onto GRBL's machine space (:mod:`~nlosplan.hardware.grbl_frame`).
    timeout, poll_s, move_timeout : float
        See :class:`~nlosplan.hardware.grbl_link.GrblLink`.
    """

    kind = "grbl"

    def __init__(self, port, *, baudrate: int = 115200, limits_mm=((0.0, 320.0), (0.0, 320.0)),
                 feed_mm_min: float = 3000.0, work_offset="auto", timeout: float = 5.0, poll_s: float = 0.05,
                 move_timeout: float = 120.0) -> None:
        (x0, x1), (y0, y1) = limits_mm
        if not all(math.isfinite(v) for v in (x0, x1, y0, y1)) or not (x0 < x1 and y0 < y1):
            raise UserError(f"gantry limits {limits_mm!r} must be finite (min, max) pairs with min < max")
        if not (math.isfinite(feed_mm_min) and feed_mm_min > 0):
            raise UserError(f"feed rate {feed_mm_min!r} mm/min must be > 0")
        work_offset = parse_work_offset(work_offset)
        super().__init__(port, baudrate, timeout=timeout, poll_s=poll_s, move_timeout=move_timeout)
        self.limits_mm = ((float(x0), float(x1)), (float(y0), float(y1)))
        self.feed_mm_min = float(feed_mm_min)
        self.work_offset = work_offset
        self.build = None
        self.settings: dict[int, float] = {}
        self.ngc: dict[str, tuple] = {}
        self.frame: WorkFrame | None = None
        self.connected_by = ""
        self.last_xy: tuple | None = None
        self.homed = False

    # ------------------------------------------------------------------ session
    def connect(self, timeout: float = 5.0) -> str:
        """Find GRBL on the port and learn its state and version.

        A banner (the board reset when the port opened) or a status report (it
        was running) is enough; when neither comes within half the timeout, a
        soft reset is sent (a GRBL halted by ALARM:1/2 answers nothing else).

        Returns
        -------
        str
            How it answered: ``banner``, ``status`` or ``reset``.

        Raises
        ------
        WrongFirmware
            Telemetrix firmware, or bytes that are neither GRBL nor Telemetrix.
        DeviceTimeout
            Nothing at all (wrong port, or the controller is off).
        """
        # the Telemetrix request first (GRBL drops control bytes), GRBL's '?' from 0.3 s: a Telemetrix board that
        # keeps running across the open answers before '?' could hang it
        found = probe_firmware(self._ser, timeout=timeout, quiet_s=0.0, query_every_s=None, grbl_after_s=0.3,
                               reset_after_s=timeout / 2, poll_s=self.repoll_s)
        if found.kind == "telemetrix":
            raise WrongFirmware(f"gantry on {self.port_name} runs Telemetrix4Arduino {found.text}, not GRBL: "
                                "use --gantry-kind telemetrix (or auto)")
        if found.kind is None:
            if found.seen:
                raise WrongFirmware(f"gantry on {self.port_name} answers, but not like GRBL 1.1 "
                                    f"({found.describe_seen()}): wrong baud rate (GRBL uses 115200) or another "
                                    "firmware on this port")
            raise DeviceTimeout(f"no answer from a gantry on {self.port_name} within {timeout:g} s (not even to "
                                "a soft reset): is this the gantry's port, and is the controller powered? (a "
                                "Telemetrix4Arduino board that reset as the port opened answers no GRBL request: "
                                "--gantry-kind telemetrix or auto)")
        self._reader.unread(found.rest)
        if found.how in ("banner", "reset"):
            self.banner = found.text
        self.connected_by = found.how
        # drain what follows ([MSG:'$H'|'$X' to unlock], a banner after an early status, answers to extra '?')
        try:
            for line in self._reader.read_until_quiet(0.15, 0.5):
                self._handle(line, "at connect")
        except (DeviceTimeout, GrblAlarm):
            pass
        st = self.status(context="at connect")
        self.alarm = -1 if st.state == "Alarm" else None
        if st.state in ("Run", "Jog", "Home"):
            st = self.wait_idle(context="at connect (it was moving)")
        elif st.state not in ("Idle", "Alarm"):
            raise UserError(f"gantry on {self.port_name} is in state {st.raw}: resume (~) or reset it (its own "
                            "controls) before nlosplan drives it")
        self.build = parse_build_info(self.send("$I"))
        version = self.build.version if self.build else (self.banner or "Grbl ?").split()[1]
        if not str(version).startswith("1.1"):
            raise WrongFirmware(f"gantry on {self.port_name} runs GRBL {version}; nlosplan speaks GRBL 1.1")
        return found.how

    def read_setup(self) -> dict[int, float]:
        """``$$`` and ``$#``: settings and stored offsets (``self.settings``, ``self.ngc``)."""
        self.settings = parse_settings(self.send("$$"))
        self.ngc = parse_ngc_parameters(self.send("$#"))
        return self.settings

    def set_setting(self, number: int, value: float) -> None:
        """``$N=value`` (one at a time, as GRBL asks)."""
        self.send(f"${int(number)}={value:g}")

    def prepare(self, *, home: bool = False, unlock: bool = False) -> None:
        """Connect, read the setup, clear an alarm only as asked, set and check the work offset.

        Raises
        ------
        UserError
            Locked in alarm and neither ``home`` nor ``unlock``; limits outside the machine space.
        GrblAlarm
            Homing failed (the message says why and what to change).
        """
        how = self.connect()
        self.read_setup()
        if self.alarm is not None:
            why = ("it was halted by an alarm (ALARM:1/2 need a soft reset, which nlosplan sent) and is now locked"
                   if how == "reset" else "it is locked in alarm (power-up lock with homing enabled, or after an "
                   "alarm)")
            if home:
                self.home()
            elif unlock:
                self.unlock()
            else:
                raise UserError(f"the gantry on {self.port_name}: {why}; pass --home (runs $H) or --unlock (sends "
                                "$X; only if you know where it is)")
        elif home:
            self.home()
        self.set_frame()

    def set_frame(self) -> WorkFrame:
        """Choose the work offset, set it (G10 L2 P1, G92.1, G54) when needed, and check it in a status report."""
        wco = tuple(a + b for a, b in zip(self.ngc.get("G54", (0, 0, 0)), self.ngc.get("G92", (0, 0, 0))))
        frame = plan_frame(self.work_offset, self.limits_mm, self.settings,
                           force_origin=bool(self.build and self.build.force_origin),
                           active_wco=self._wco[:2] if self._wco else wco[:2])
        if frame.mode != "keep":
            g54, g92 = self.ngc.get("G54", (0.0, 0.0, 0.0)), self.ngc.get("G92", (0.0, 0.0, 0.0))
            changed = False
            if any(abs(a - b) > TOL_MM / 2 for a, b in zip(g54[:2], frame.offset_mm)):
                self.send(f"G10 L2 P1 X{frame.offset_mm[0]:.3f} Y{frame.offset_mm[1]:.3f}")   # stored in EEPROM
                changed = True
            if any(abs(v) > 0 for v in g92):
                self.send("G92.1")
                changed = True
            self.send("G54")
            if changed:
                self.ngc = parse_ngc_parameters(self.send("$#"))
        self.frame = frame
        self._check_wco(self._report_with_wco())
        return frame

    def _report_with_wco(self) -> tuple:
        for _ in range(40):   # GRBL sends WCO at the latest every 10 idle reports, and at once after a change
            st = self.status(context="reading the work offset")
            if st.wco is not None:
                return st.wco
            time.sleep(0.01)
        raise DeviceTimeout(f"gantry on {self.port_name}: no status report with the work offset (WCO) in 40")

    def _check_wco(self, wco) -> None:
        f = self.frame
        if f is not None and any(abs(a - b) > TOL_MM for a, b in zip(wco[:2], f.offset_mm)):
            raise FrameChanged(f"gantry on {self.port_name}: the work offset is ({wco[0]:g}, {wco[1]:g}) mm but "
                               f"nlosplan set ({f.offset_mm[0]:g}, {f.offset_mm[1]:g}) mm: something else sent "
                               "G10/G92/G55; user-frame positions would be wrong (rerun to set it again)")

    def home(self, timeout: float = 120.0) -> Status:
        """``$H`` homing cycle (needs ``$22=1``); on failure the alarm says why (Z first, stuck pins)."""
        before = self.status(context="before homing")
        try:
            self.send("$H", timeout=timeout)
        except GrblAlarm as exc:   # GRBL resets itself after a failed cycle: its ok, then a banner
            try:
                for line in self._reader.read_until_quiet(0.2, 2.0):
                    if line.strip().startswith("Grbl "):
                        self.banner = line.strip()
            except DeviceTimeout:
                pass
            after = self.status(context="after homing failed")
            self.alarm = exc.code
            raise GrblAlarm(exc.code, "while homing ($H)", homing_diagnosis(exc.code, before, after)) from None
        self.alarm = None
        self.homed = True
        return self.wait_idle(context="after homing")

    def unlock(self) -> None:
        """``$X``: clear an alarm lock without homing (only when the user asks for it)."""
        self.send("$X")
        self.alarm = None

    def recover(self, *, home: bool = False, unlock: bool = False) -> Status:
        """Clear an alarm by GRBL's rules: soft reset first when it is halted (ALARM:1/2), then ``$H`` or ``$X``."""
        if not (home or unlock):
            raise UserError("clearing a gantry alarm needs home=True ($H) or unlock=True ($X)")
        if self.alarm in CRITICAL_ALARMS:
            self.soft_reset()
        else:
            try:
                self.status(timeout=1.0)
            except DeviceTimeout:   # halted (an alarm this driver did not see): only a reset is heard
                self.soft_reset()
        self.home() if home else self.unlock()
        if self.frame is not None:
            self._check_wco(self._report_with_wco())
        return self.status()

    # ------------------------------------------------------------------ motion in the user frame
    @property
    def referenced(self) -> bool:
        """Whether positions are referenced to the machine: homed in this session, or GRBL kept running (a status
        report answered the probe, no reset banner), so it counts from where it counted before."""
        return self.homed or self.connected_by == "status"

    def origin_xy(self) -> tuple[float, float]:
        """The user-frame position of machine zero (where an unhomed GRBL counts from after a reset)."""
        off = self.frame.offset_mm if self.frame is not None else (0.0, 0.0)
        return -float(off[0]) + 0.0, -float(off[1]) + 0.0

    def check_limits(self, x_mm: float, y_mm: float) -> None:
        """Raise :class:`LimitError` when (x, y) mm is outside the limits (nothing is sent)."""
        check_box(self.limits_mm, x_mm, y_mm)

    def move_to(self, x_mm: float, y_mm: float, *, feed_mm_min: float | None = None,
                wait: bool = True) -> GantryPosition | None:
        """Absolute move in the user frame (``G90 G21 G1 X Y F``: work coordinates); waits for Idle.

        Returns
        -------
        GantryPosition or None
            The position reported at the target (None with ``wait=False``).

        Raises
        ------
        LimitError
            Target outside the limits (checked before sending).
        GrblAlarm, GrblError, DeviceTimeout, ConnectionLost, FrameChanged
        """
        x, y = float(x_mm), float(y_mm)
        self.check_limits(x, y)
        feed = self.feed_mm_min if feed_mm_min is None else float(feed_mm_min)
        if not (math.isfinite(feed) and feed > 0):
            raise UserError(f"feed rate {feed_mm_min!r} mm/min must be > 0")
        self.send(f"G90 G21 G1 X{x:.3f} Y{y:.3f} F{feed:.0f}", timeout=max(self.timeout, self.MOTION_OK_S))
        if not wait:
            return None
        context = f"moving to ({x:.3f}, {y:.3f}) mm"
        pos = self._position(self.wait_idle(context=context))
        # GRBL may still report Idle right after the move's 'ok', before the block starts (seen with the real
        # firmware under load): Idle away from the target is polled again, for at most START_WAIT_S
        give_up = time.monotonic() + self.START_WAIT_S
        while not self._reached(pos.xy_mm, (x, y)) and time.monotonic() < give_up:
            time.sleep(self.poll_s)
            pos = self._position(self.wait_idle(context=context))
        return pos

    #: Longest wait (s) for a move to start when GRBL still reports Idle away from the target after its 'ok'.
    START_WAIT_S = 1.0
    #: Seconds a motion line may wait for its ``ok``: GRBL answers when the block enters its planner buffer
    #: (later while the buffer is full), and an emulated gantry answers late while its process is busy (the
    #: emulated sensor's simulator compiling holds the interpreter for seconds: a park after SIGTERM on a loaded
    #: CI host waited 5 s in vain). A link that died names itself after this long during a move.
    MOTION_OK_S = 30.0

    def _reached(self, xy, target) -> bool:
        """Within half a step (``$100``/``$101``) plus 0.01 mm of ``target`` on both axes."""
        tol = [0.01 + 0.5 / self.settings.get(k, 1e9) for k in (100, 101)]
        return all(abs(a - b) <= t for a, b, t in zip(xy, target, tol))

    def where(self) -> GantryPosition:
        """The reported position now, in the user frame (and raw MPos/WCO)."""
        return self._position(self.status())

    def _position(self, st: Status) -> GantryPosition:
        if st.wco is not None:
            self._check_wco(st.wco)
        wco = self.frame.offset_mm if self.frame is not None else (self._wco or (0.0, 0.0))[:2]
        mpos = st.mpos if st.mpos is not None else tuple(a + b for a, b in zip(st.wpos, wco))
        xy = (round(mpos[0] - wco[0], 4), round(mpos[1] - wco[1], 4))
        self.last_xy = xy
        return GantryPosition(xy, {"mpos_mm": list(mpos), "wco_mm": list(wco)}, st.state)

    def blocked(self) -> str | None:
        """Why the gantry must not move now (an alarm), or None."""
        if self.alarm is None:
            return None
        code = f"ALARM:{self.alarm}" if self.alarm and self.alarm > 0 else "Alarm state"
        return f"in alarm ({code})"

    def describe(self) -> dict:
        """Port, firmware, settings that matter and the user frame (stored with every capture)."""
        s = self.settings
        out = {"kind": "grbl", "port": self.port_name, "banner": self.banner, "connected_by": self.connected_by,
               "version": self.build.version if self.build else None, "build": self.build.build if self.build else None,
               "options": self.build.options if self.build else None, "feed_mm_min": self.feed_mm_min,
               "limits_mm": [list(v) for v in self.limits_mm],
               "settings": {f"${k}": s[k] for k in (20, 22, 23, 100, 101, 110, 111, 120, 121, 130, 131) if k in s}}
        if self.frame is not None:
            out.update(self.frame.describe())
        return out
