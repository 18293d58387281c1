"""TMF8828 driver for the ams Arduino firmware (DENALI's variant) over pyserial.

A thin protocol class over an injected transport (STYLE.md 4): the framing is
:mod:`nlosplan.hardware.tmf8828_protocol`, the line reads are
:class:`~nlosplan.hardware.transport.LineReader` with deadlines.

Examples
--------
>>> with TMF8828("/dev/ttyACM0", baudrate=2_000_000) as lidar:   # doctest: +SKIP
...     lidar.start("3x3", "short")
...     frame = lidar.read_frame(fresh=True)      # counts: (3, 3, 128) int64
...     lidar.stop()
"""

from __future__ import annotations

import time

from nlosplan.errors import UserError
from nlosplan.hardware.tmf8828_protocol import Frame, FrameAssembler, RangeMode, ZoneMode, start_sequence
from nlosplan.hardware.transport import (TMF8828_BAUDS, ConnectionLost, DeviceTimeout, LineReader, close_serial,
                                         open_serial)

__all__ = ["TMF8828", "SensorError", "SensorGarbage"]


class SensorError(RuntimeError):
    """The sensor firmware did not do what it was asked (no answer to a command, no frames)."""


class SensorGarbage(SensorError):
    """The port answers with bytes that are not the ams firmware's protocol (wrong baud rate, another device).

    Not worth a retry: reconnecting does not change what is on the port.
    """


def _noise(line: str) -> bool:
    """A line no firmware prints: bytes that do not decode as ASCII, or control characters."""
    return any(ch == "\ufffd" or (ord(ch) < 32 and ch != "\t") or ord(ch) > 126 for ch in line)


class TMF8828:
    """A TMF8828 on the ams Arduino firmware.

    Parameters
    ----------
    port : str or serial object
        Port name / pyserial URL, or an open pyserial object (not closed by :meth:`close`).
    baudrate : int
        115200, 1,000,000 or 2,000,000 (the firmware's build setting; DENALI: 2,000,000).
    quiet_s : float
        A command's answer ends after this much silence (the firmware prints a
        few lines per command and no terminator).
    command_timeout : float
        Seconds to wait for the first byte of a command's answer.
    frame_timeout : float
        Default seconds :meth:`read_frame` waits for a complete frame.
    """

    def __init__(self, port, *, baudrate: int = 2_000_000, quiet_s: float = 0.2, command_timeout: float = 3.0,
                 frame_timeout: float = 5.0) -> None:
        if int(baudrate) not in TMF8828_BAUDS:
            raise UserError(f"baud rate {baudrate} is not a TMF8828 firmware rate; allowed: "
                            f"{', '.join(map(str, TMF8828_BAUDS))}")
        self.port_name = port if isinstance(port, str) else getattr(port, "port", None) or repr(port)
        self._port_arg = port
        self.baudrate = int(baudrate)
        self.quiet_s, self.command_timeout, self.frame_timeout = quiet_s, command_timeout, frame_timeout
        self.garbage_s = 3.0   # lines but no histogram data for this long: not the sensor's protocol
        self._ser, self._owned = open_serial(port, self.baudrate)
        self._reader = LineReader(self._ser)
        self.zones: ZoneMode | None = None
        self.range_mode: RangeMode | None = None
        self.measuring = False
        self.assembler: FrameAssembler | None = None
        self.transcript: list[tuple[str, list[str]]] = []   # (command, answer lines) of the start sequence
        self.reconnects = 0

    # ------------------------------------------------------------------ commands
    def command(self, char: str) -> list[str]:
        """Send a single-character command; returns its answer lines (until ``quiet_s`` of silence).

        ``m`` (measure) returns at its first answer line: the firmware then
        streams data without pause.

        Raises
        ------
        SensorError
            No answer within ``command_timeout``.
        """
        if len(char) != 1:
            raise UserError(f"TMF8828 commands are single characters, not {char!r}")
        self._reader.write(char.encode("ascii"))
        try:
            if char == "m":
                lines = [self._reader.readline(self.command_timeout)]
            else:
                lines = self._reader.read_until_quiet(self.quiet_s, self.command_timeout)
        except DeviceTimeout:
            raise SensorError(f"TMF8828 on {self.port_name}: no answer to command {char!r} within "
                              f"{self.command_timeout:g} s (wrong port or baud rate {self.baudrate}?)") from None
        if lines and all(_noise(ln) for ln in lines):
            raise SensorGarbage(f"TMF8828 on {self.port_name} answers command {char!r} with noise ({len(lines)} "
                                f"lines, e.g. {lines[0][:24]!r}): wrong baud rate (this one {self.baudrate}; the ams "
                                "firmware runs at 115200, 1000000 or 2000000, DENALI's at 2000000) or not the "
                                "sensor's port")
        self.transcript.append((char, lines))
        return lines

    def start(self, zones: ZoneMode | str = "3x3", range_mode: RangeMode | str = "short") -> dict:
        """Run the DENALI start sequence for a mode and start measuring.

        Returns
        -------
        dict
            The firmware configuration: ``zones``, ``range``, ``baudrate``,
            ``sequence`` (the commands) and ``answers`` (first answer line per command).
        """
        try:
            zones, range_mode = ZoneMode(zones), RangeMode(range_mode)
        except ValueError as exc:
            raise UserError(f"TMF8828 mode: {exc}; allowed zones 3x3, 4x4, 8x8 and range short, long") from None
        self._reader.flush()
        self.transcript = []
        seq = start_sequence(zones, range_mode)
        for char in seq:
            self._check_answer(char, self.command(char), zones, range_mode)
        self.zones, self.range_mode = zones, range_mode
        self.assembler = FrameAssembler(zones)
        self.measuring = True
        return self.firmware_config()

    def _check_answer(self, char: str, answer: list[str], zones: ZoneMode, range_mode: RangeMode) -> None:
        """Check a start command's answer by what the firmware prints; press ``z`` again until it dumps raw.

        ``z`` cycles the dump mode and answers ``Histogram is N`` (1 = raw), so a firmware that was not reset
        (no DTR reset on open) may need more presses. After ``m`` the firmware's state line names its mode
        (``TMF8828 state=measure`` in 8x8, ``TMF882x state=...`` in 3x3/4x4): a mismatch is an error. ``O``
        prints only a ``#Conf`` line, which names no range, and ``o`` nothing when it works: their effect
        cannot be read back (the sequence is deterministic after ``d`` and the download, which resets the
        firmware to long range and no dumps). Answers not recognised are left alone.
        """
        for _ in range(4):
            text = " ".join(answer).lower()
            if char == "z" and "histogram is" in text:
                again = text.split("histogram is")[1].strip()[:1] != "1"
            elif char == "m":
                self._check_mode(answer, zones)
                return
            else:
                return
            if not again:
                return
            answer = self.command(char)
        raise SensorError(f"TMF8828 on {self.port_name}: command {char!r} did not reach the wanted state "
                          f"(last answer {' | '.join(answer)[:80]!r})")

    def _check_mode(self, answer: list[str], zones: ZoneMode) -> None:
        line = next((ln for ln in answer if " state=" in ln), None)
        if line is None:
            return
        want = "TMF8828" if zones is ZoneMode.Z8X8 else "TMF882x"
        if not line.startswith(want) or not line.endswith("state=measure"):
            raise SensorError(f"TMF8828 on {self.port_name}: after 'm' the firmware says {line!r}, not "
                              f"'{want} state=measure' ({zones.value} zones): it did not start in this mode")

    def firmware_config(self) -> dict:
        """What the sensor was started with (stored with every capture)."""
        return {"zones": None if self.zones is None else self.zones.value,
                "range": None if self.range_mode is None else self.range_mode.value,
                "baudrate": self.baudrate, "sequence": "".join(c for c, _ in self.transcript),
                "answers": {c: (lines[0][:80] if lines else "") for c, lines in self.transcript}}

    def stop(self) -> None:
        """Stop measuring (``s``); the port stays open. Safe to call twice or on a dead link."""
        if not self.measuring:
            return
        self.measuring = False
        try:
            self._reader.write(b"s")
            self._reader.read_until_quiet(self.quiet_s, self.command_timeout)
        except (DeviceTimeout, ConnectionLost):
            pass

    # ------------------------------------------------------------------ frames
    def read_frame(self, timeout: float | None = None, *, fresh: bool = False, skip: int = 1) -> Frame:
        """The next complete frame.

        Parameters
        ----------
        timeout : float, optional
            Seconds to wait (default ``frame_timeout``).
        fresh : bool
            Throw away buffered input first and then ``skip`` complete frames,
            so the frame returned was measured after this call (use it after a
            gantry move: a frame in flight may have integrated during the move).

        Raises
        ------
        SensorError
            Not measuring, or no complete frame within ``timeout``.
        ConnectionLost
            The port failed.
        """
        if self.assembler is None or not self.measuring:
            raise SensorError("TMF8828 is not measuring; call start() first")
        timeout = self.frame_timeout if timeout is None else timeout
        if fresh:
            self._reader.flush()
            self.assembler.reset()
        to_skip = skip if fresh else 0
        t0 = time.monotonic()
        deadline = t0 + timeout
        data_seen, lines, sample = False, 0, ""
        while True:
            now = time.monotonic()
            left = deadline - now
            if left <= 0:
                raise SensorError(f"TMF8828 on {self.port_name}: no complete {self.zones.value} frame within "
                                  f"{timeout:g} s ({self.assembler.stats.dropped_frames} dropped so far)")
            if now - t0 > self.garbage_s and lines >= 20 and not data_seen:
                raise SensorGarbage(f"TMF8828 on {self.port_name}: {lines} lines in {now - t0:.1f} s, "
                                    f"none of them histogram data (e.g. {sample[:30]!r}): another device on this "
                                    "port, a wrong baud rate, or a firmware that does not stream histograms")
            try:
                line = self._reader.readline(min(left, 0.5))
            except DeviceTimeout:
                continue
            lines += 1
            sample = sample or line
            data_seen = data_seen or line.lstrip()[:4] in ("#Raw", "#Cal", "#Obj")
            for frame in self.assembler.feed(line):
                if to_skip:
                    to_skip -= 1
                    continue
                return frame

    @property
    def stats(self) -> dict:
        """Frame assembler counters (frames, dropped frames, garbage lines, ...)."""
        return {} if self.assembler is None else self.assembler.stats.to_dict()

    # ------------------------------------------------------------------ link
    def reconnect(self, timeout: float = 10.0) -> None:
        """Reopen the port by name (after an unplug) and restart in the same mode.

        Raises
        ------
        SensorError
            The port was handed in open (cannot be reopened here), or it does
            not come back within ``timeout`` seconds.
        """
        if not self._owned:
            raise SensorError("the TMF8828 port was handed in open; reconnect it yourself")
        zones, range_mode = self.zones, self.range_mode
        stats = self.assembler.stats if self.assembler else None
        self._close_port()
        deadline = time.monotonic() + timeout
        last = None
        while time.monotonic() < deadline:
            try:
                self._ser, _ = open_serial(self._port_arg, self.baudrate)
                self._reader = LineReader(self._ser)
                if zones is not None:
                    self.start(zones, range_mode)
                    if stats is not None:
                        self.assembler.stats = stats
                self.reconnects += 1
                return
            except (UserError, SensorError, ConnectionLost) as exc:
                last = exc
                self._close_port()
                time.sleep(0.2)
        raise SensorError(f"TMF8828 on {self.port_name} did not come back within {timeout:g} s ({last})")

    def _close_port(self) -> None:
        close_serial(self._ser, self._owned)

    def close(self) -> None:
        """Stop measuring and close the port (if this driver opened it)."""
        self.stop()
        self._close_port()

    def __enter__(self) -> "TMF8828":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
