"""Progress of long work on stderr: a tqdm bar on a terminal, a line every few seconds otherwise.

One helper for every command that can run longer than a few seconds. Progress
goes to stderr, so it shows also with ``--json`` (stdout stays the JSON).
Off a terminal (a log file, a pipe, CI) a line is printed at most every
``every`` seconds, plus one when a new stage starts and one at the end::

    nlosplan dataset build: 120/600 captures (20 %), 14 s, about 56 s left

Examples
--------
>>> with Progress("dataset build", total=600, unit="capture") as p:  # doctest: +SKIP
...     for batch in batches:
...         ...
...         p.update(len(batch))
"""

from __future__ import annotations

import sys
import time
from typing import TextIO

__all__ = ["Progress", "EVERY_S"]

#: Seconds between two progress lines off a terminal.
EVERY_S = 5.0


class Progress:
    """Counts of work done against planned, shown on stderr.

    Parameters
    ----------
    desc : str
        What runs, e.g. ``"dataset build"``.
    total : int, optional
        Planned units (None: unknown yet; :meth:`set` may give it later).
    unit : str
        Name of one unit, e.g. ``"capture"``.
    enabled : bool
        False shows nothing (e.g. ``--quiet``).
    stream : file, optional
        Default ``sys.stderr``.
    every : float
        Seconds between lines off a terminal.
    tty : bool, optional
        Force the terminal (tqdm) or line mode; default: ``stream.isatty()``.
    """

    def __init__(self, desc: str, total: int | None = None, unit: str = "step", *, enabled: bool = True,
                 stream: TextIO | None = None, every: float = EVERY_S, tty: bool | None = None):
        self.desc, self.total, self.unit = desc, total, unit
        self.done = 0
        self.text = ""
        self.stage_name: str | None = None
        self.enabled = enabled
        self.stream = sys.stderr if stream is None else stream
        self.every = every
        self.t0 = time.monotonic()
        self._last = self.t0
        self._rate_from = (self.t0, 0)   # (time, units done) the "s left" estimate counts from
        self._bar = None
        self._printed = False
        if tty is None:
            try:
                tty = self.stream.isatty()
            except (AttributeError, ValueError):
                tty = False
        if enabled and tty:
            from tqdm import tqdm

            self._bar = tqdm(total=total, desc=desc, unit=unit, file=self.stream, leave=False, dynamic_ncols=True)

    # ------------------------------------------------------------------ context
    def __enter__(self) -> "Progress":
        return self

    def __exit__(self, exc_type, *exc) -> None:
        self.close(finished=exc_type is None)

    def close(self, finished: bool = True) -> None:
        """Close the bar; off a terminal, a last line when something was shown and the work finished."""
        if self._bar is not None:
            self._bar.close()
            self._bar = None
        elif self.enabled and finished and self._printed:
            self._line(final=True)

    # ------------------------------------------------------------------ updates
    def update(self, n: int = 1, text: str | None = None) -> None:
        """``n`` more units done (and an optional short note of the current item)."""
        self.set(self.done + n, text=text)

    def set(self, done: int, total: int | None = None, text: str | None = None) -> None:
        """Units done so far (and the total when it becomes known or changes)."""
        if int(done) < self.done:   # the counts started over: the time left counts from here
            self._rate_from = (time.monotonic(), 0)
        self.done = int(done)
        if total is not None:
            self.total = int(total)
        if text is not None:
            self.text = text
        self._show()

    def set_postfix_str(self, text: str, refresh: bool = True) -> None:
        """tqdm's name for a short note of the current item (shown with the counts)."""
        self.text = text
        if refresh:
            self._show()

    def refresh(self) -> None:
        """Show the current state (at most one line per ``every`` seconds off a terminal)."""
        self._show()

    def stage(self, name: str, total: int | None = None, unit: str | None = None) -> None:
        """A new stage of the work (counting ``unit``, when given); off a terminal its first line is printed at once."""
        if name == self.stage_name:
            return
        self.stage_name = name
        if total is not None:
            self.total = total
        if unit is not None and unit != self.unit:   # counts of another kind: the old ones do not carry over
            self.unit, self.done, self.total = unit, 0, total
            if self._bar is not None:
                self._bar.unit = unit
        self._rate_from = (time.monotonic(), self.done)   # a stage's pace is its own
        if self._bar is not None:
            self._bar.set_description_str(f"{self.desc}: {name}", refresh=True)
        elif self.enabled:
            self._line()

    def note(self, text: str) -> None:
        """A one-off line (e.g. what is about to start), on a terminal above the bar."""
        if not self.enabled:
            return
        if self._bar is not None:
            self._bar.write(f"nlosplan {self.desc}: {text}", file=self.stream)
        else:
            print(f"nlosplan {self.desc}: {text}", file=self.stream, flush=True)
            self._printed = True

    # ------------------------------------------------------------------ output
    def _show(self) -> None:
        if not self.enabled:
            return
        if self._bar is not None:
            if self.total is not None and self._bar.total != self.total:
                self._bar.total = self.total
            self._bar.n = self.done
            if self.text:
                self._bar.set_postfix_str(self.text[:60], refresh=False)
            self._bar.refresh()
            return
        now = time.monotonic()
        if now - self._last >= self.every:
            self._line()

    def line_text(self, final: bool = False) -> str:
        """The line shown off a terminal."""
        elapsed = time.monotonic() - self.t0
        head = f"nlosplan {self.desc}" + (f" [{self.stage_name}]" if self.stage_name else "")
        units = f"{self.unit}s" if not self.unit.endswith("s") else self.unit
        if self.total:
            part = f"{self.done}/{self.total} {units} ({100 * self.done / self.total:.0f} %)"
        else:
            part = f"{self.done} {units}"
        left = ""
        since, done0 = self._rate_from
        if self.total and done0 < self.done < self.total and not final:
            pace = (time.monotonic() - since) / (self.done - done0)   # seconds per unit in this stage
            left = f", about {pace * (self.total - self.done):.0f} s left"
        tail = f" - {self.text[:60]}" if self.text and not final else ""
        return f"{head}: {'done, ' if final else ''}{part}, {elapsed:.0f} s{left}{tail}"

    def _line(self, final: bool = False) -> None:
        self._last = time.monotonic()
        print(self.line_text(final), file=self.stream, flush=True)
        self._printed = True
