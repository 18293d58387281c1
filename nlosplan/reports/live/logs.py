"""The live server's logs: one line a record, the action token never in them.

Tornado logs a failed request with its whole URI (``500 GET /?token=... (127.0.0.1)``,
``Uncaught exception GET /?token=...``), and Bokeh logs every malformed websocket
message or refused origin with a traceback. While a page is served,
:func:`server_logs` routes the ``tornado``, ``bokeh`` and ``asyncio`` loggers (and
anything that reaches the root logger) through one handler on stderr whose
:class:`Redact` filter

- replaces the value of every ``token=`` query argument, and the token itself
  wherever it appears, by ``[redacted]`` (in the message, its arguments and the
  exception text);
- writes one line per record: line breaks and runs of blanks become one blank, an
  exception is shown as its type and message (no traceback), control characters a
  client sent are shown escaped (never sent to the terminal), and a line is cut at
  :data:`MAX_LINE` characters;
- says a refused websocket origin in the live view's own words (Bokeh's line advises
  its own command-line flag);
- writes at most :data:`BURST` lines per :data:`WINDOW_S` seconds and then says
  how many it dropped, so a local client sending malformed messages in a loop cannot
  flood the run's terminal.
"""

from __future__ import annotations

import logging
import re
import sys
import time
from contextlib import contextmanager

__all__ = ["BURST", "MAX_LINE", "WINDOW_S", "REDACTED", "Redact", "redact", "server_logs"]

REDACTED = "[redacted]"
#: At most this many lines ...
BURST = 20
#: ... per this many seconds.
WINDOW_S = 10.0
_TOKEN_ARG = re.compile(r"(?i)((?:^|[?&;\s\"'])token=)[^&;\s\"'#]*")
_BLANKS = re.compile(r"\s+")
#: A log line is cut after this many characters.
MAX_LINE = 400
_REFUSED = re.compile(r"Refusing websocket connection from Origin '([^']*)'.*")
LOGGERS = ("tornado", "bokeh", "asyncio")


def redact(text: str, secrets=()) -> str:
    """``text`` with the value of every ``token=`` argument and every secret in ``secrets`` redacted.

    Parameters
    ----------
    text : str
    secrets : iterable of str
        Literal values never to show (the page's token); empty strings are ignored.

    Returns
    -------
    str
    """
    for s in secrets:
        if s:
            text = text.replace(s, REDACTED)
    return _TOKEN_ARG.sub(lambda m: m.group(1) + REDACTED, text)


class Redact(logging.Filter):
    """Rewrite a record as one redacted line (see the module's text); drop records past the rate limit.

    Parameters
    ----------
    secrets : iterable of str
        Literal values never to show (the page's token).
    burst, window_s : int, float
        At most ``burst`` records pass per ``window_s`` seconds; the next one that passes says how many were
        dropped.
    clock : callable
        Seconds (monotonic); a test passes its own.
    """

    def __init__(self, secrets=(), *, burst: int = BURST, window_s: float = WINDOW_S, clock=time.monotonic):
        super().__init__()
        self.secrets = tuple(s for s in secrets if s)
        self.burst, self.window_s, self.clock = burst, window_s, clock
        self._window_start = -float("inf")
        self._passed = 0
        self.dropped = 0

    def filter(self, record: logging.LogRecord) -> bool:
        now = self.clock()
        if now - self._window_start >= self.window_s:
            self._window_start, self._passed = now, 0
        if self._passed >= self.burst:
            self.dropped += 1
            return False
        self._passed += 1
        try:
            text = record.getMessage()
        except Exception as exc:  # noqa: BLE001 - a record whose arguments do not fit its format
            text = f"{record.msg!s} (unformattable arguments: {type(exc).__name__})"
        if record.exc_info and record.exc_info[1] is not None:
            exc = record.exc_info[1]
            if f"{exc}" not in text:
                text += f" [{type(exc).__name__}: {exc}]"
        text = _BLANKS.sub(" ", redact(text, self.secrets)).strip()
        text = _REFUSED.sub(lambda m: f"refused a websocket from a page at {m.group(1)}: not an allowed origin "
                                      "(nlosplan serve --allow-origin HOST:PORT adds one)", text)
        text = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)
        if len(text) > MAX_LINE:
            text = text[:MAX_LINE - 1] + "…"
        if self.dropped:
            text += f" ({self.dropped} earlier log lines dropped: more than {self.burst} in {self.window_s:g} s)"
            self.dropped = 0
        record.msg = text
        record.args = None
        record.exc_info = record.exc_text = record.stack_info = None
        return True


@contextmanager
def server_logs(secrets=(), *, stream=None, prefix: str = "nlosplan serve"):
    """While the block runs, the server's loggers write redacted single lines to ``stream`` (stderr).

    Parameters
    ----------
    secrets : iterable of str
        Values never to log (the page's token).
    stream : file, optional
        Where the lines go (default: ``sys.stderr`` at the time of the call).
    prefix : str
        Each line starts ``PREFIX: LOGGER: message``.

    Notes
    -----
    ``tornado`` and ``bokeh`` log errors only (tornado's access log of a 500 included; a 404 is not worth a
    line), ``asyncio`` and the root logger warnings and errors. The loggers' handlers, levels and
    propagation are restored when the block ends.
    """
    handler = logging.StreamHandler(sys.stderr if stream is None else stream)
    handler.setFormatter(logging.Formatter(f"{prefix}: %(name)s: %(message)s"))
    handler.addFilter(Redact(secrets))
    saved = []
    for name, level in ((LOGGERS[0], logging.ERROR), (LOGGERS[1], logging.ERROR), (LOGGERS[2], logging.WARNING),
                        ("", None)):
        lg = logging.getLogger(name)
        saved.append((lg, lg.handlers[:], lg.level, lg.propagate))
        if name:
            lg.handlers = [handler]
            lg.setLevel(level)
            lg.propagate = False
        else:   # the root: what other libraries log goes through the same filter instead of Python's last resort
            lg.handlers = [handler]
            lg.setLevel(logging.WARNING)
    try:
        yield handler
    finally:
        for lg, handlers, level, propagate in saved:
            lg.handlers, lg.propagate = handlers, propagate
            lg.setLevel(level)
