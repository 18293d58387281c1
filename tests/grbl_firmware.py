"""The real GRBL 1.1h firmware for tests: built from ``../shared/vendor`` with grbl-sim, run on a pty.

``build_grbl_sim(dest)`` copies GRBL 1.1h and grbl-sim into ``dest`` and
compiles the simulator with the two harness fixes of ``vendor/README.md``
(``-fcommon`` for gcc >= 10; unbuffered stdin so every byte of a write is
seen at once). Nothing of the vendor tree is imported or copied into the
package; the build lives in a temporary folder.

:class:`GrblFirmware` runs ``grbl_sim.exe`` with its stdin/stdout on a pty
of its own and bridges that to a port name the driver opens (the project's
:class:`~nlosplan.hardware.emulators.pty.PtyDevice`, so opening and closing
the port behave as for the emulators). :class:`MirrorGrbl` is the project's
emulator set up like grbl-sim (no reset on port open, every input pin
active), so the same scenarios run on both.

grbl-sim runs the firmware's main loop and its "interrupts" (stepper, serial)
in two threads whose only exclusion is a flag (``cli()``/``sei()`` set a bit
the other thread reads unlocked). On two cores the stepper interrupt runs
truly in parallel with the main loop's critical sections: measured here, 3 of
15 ``$H`` cycles hung (no ``ok`` in 20 s) and a move ended short while
reporting Idle. Pinned to one core the threads only interleave at scheduler
switches: 0 of 45. So :class:`GrblFirmware` pins the simulator to one core
(a harness fix, like the two of the build; the firmware is unchanged).
"""

from __future__ import annotations

import os
import pty
import shutil
import subprocess
import time
import tty
from pathlib import Path

from nlosplan.hardware.emulators.grbl import EmulatedGrbl
from nlosplan.hardware.emulators.pty import PtyDevice

VENDOR = Path(__file__).resolve().parents[1].parent / "shared" / "vendor"
SIM_PINS = "PXYZRHS"   # grbl-sim reads every input pin as active


def missing_tools() -> list[str]:
    """The build tools that are not installed (gcc, make)."""
    return [t for t in ("gcc", "make") if shutil.which(t) is None]


def build_grbl_sim(dest: Path) -> Path:
    """Build ``grbl_sim.exe`` in ``dest`` (about 5 s of CPU); returns its path.

    Raises
    ------
    FileNotFoundError
        The vendor sources are not at ``../shared/vendor``.
    RuntimeError
        The build failed (with the end of its log).
    """
    for part in ("grbl/grbl", "grbl-sim"):
        if not (VENDOR / part).is_dir():
            raise FileNotFoundError(f"GRBL sources not found at {VENDOR / part} (see shared/vendor/README.md)")
    dest = Path(dest)
    shutil.copytree(VENDOR / "grbl", dest / "grbl")
    sim = dest / "grbl" / "grbl" / "grbl-sim"
    shutil.copytree(VENDOR / "grbl-sim", sim)
    for p in [dest, *dest.rglob("*")]:
        p.chmod(p.stat().st_mode | 0o200)   # the vendor tree is read-only
    main = sim / "main.c"
    text = main.read_text()
    if "setvbuf(stdin, NULL, _IONBF, 0);\n  platform_init();" not in text:
        text = text.replace("  platform_init(); ", "  setvbuf(stdin, NULL, _IONBF, 0);\n  platform_init(); ", 1)
        main.write_text(text)
    out = subprocess.run(["make", "new", "FLAGS=-g -O2 -fcommon"], cwd=sim, capture_output=True, text=True)
    exe = sim / "grbl_sim.exe"
    if out.returncode != 0 or not exe.exists():
        raise RuntimeError(f"grbl-sim build failed ({out.returncode}): {(out.stdout + out.stderr)[-800:]}")
    return exe


class GrblFirmware(PtyDevice):
    """The real GRBL 1.1h (grbl-sim) behind a port name; settings persist in ``workdir/EEPROM.DAT``.

    Parameters
    ----------
    exe : Path
        ``grbl_sim.exe``.
    workdir : Path
        Its working folder (a fresh one starts from factory defaults).
    """

    kind = "real"

    def __init__(self, exe: Path, workdir: Path) -> None:
        super().__init__("grbl", tick_s=0.001)
        self.exe, self.workdir = Path(exe), Path(workdir)
        self.workdir.mkdir(parents=True, exist_ok=True)
        self.proc = None
        self._fw = -1
        self.boot_text = ""
        self._launch()

    def _launch(self) -> None:
        master, slave = pty.openpty()
        tty.setraw(slave)
        # -n: no comment prefix on GRBL's lines; -b /dev/null: the planner-block log stays off the serial stream
        self.proc = subprocess.Popen([str(self.exe), "-n", "-b", os.devnull], stdin=slave, stdout=slave,
                                     stderr=subprocess.DEVNULL, cwd=self.workdir, start_new_session=True)
        os.close(slave)
        os.set_blocking(master, False)
        text, deadline = b"", time.monotonic() + 20.0
        while b"Grbl 1.1" not in text or not text.endswith(b"\r\n"):
            if time.monotonic() > deadline or self.proc.poll() is not None:
                raise RuntimeError(f"grbl-sim did not boot (exit {self.proc.poll()}): {text[-200:]!r}")
            try:
                text += os.read(master, 4096)
            except BlockingIOError:
                time.sleep(0.01)
        time.sleep(0.05)
        try:
            text += os.read(master, 4096)
        except BlockingIOError:
            pass
        self.boot_text = text.decode("ascii", errors="replace")
        self._pin_to_one_core()
        self._fw = master   # from now on the bridge thread forwards what the firmware says
        self.drop_output()

    def _pin_to_one_core(self) -> None:
        """Put every thread of grbl-sim on one core (both exist once it has booted; see the module's note)."""
        core = min(os.sched_getaffinity(0))
        for tid in os.listdir(f"/proc/{self.proc.pid}/task"):
            try:
                os.sched_setaffinity(int(tid), {core})
            except ProcessLookupError:   # that thread ended between the listing and now: nothing to pin
                continue

    def on_bytes(self, data: bytes) -> None:
        if self._fw >= 0:
            os.write(self._fw, data)

    def tick(self, now: float) -> None:
        if self._fw < 0:
            return
        try:
            data = os.read(self._fw, 4096)
        except (BlockingIOError, OSError):
            return
        if data:
            self.send(data)

    def _stop_process(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(timeout=5)
        if self._fw >= 0:
            os.close(self._fw)
            self._fw = -1

    def power_cycle(self) -> None:
        """Stop and restart the firmware (EEPROM kept); what it prints while booting is dropped."""
        fw, self._fw = self._fw, -1
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(timeout=5)
        if fw >= 0:
            os.close(fw)
        self._launch()
        self.drop_output()

    def close(self) -> None:
        self._stop_process()
        super().close()


def mirror_grbl(time_scale: float = 1.0) -> EmulatedGrbl:
    """The project's emulator set up as grbl-sim runs: no reset on port open, every input pin active."""
    return EmulatedGrbl(time_scale=time_scale, reset_on_open=False, pins=SIM_PINS)
