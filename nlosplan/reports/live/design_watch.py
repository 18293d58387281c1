"""What the design page shows, read from a design output folder while the run writes it (or after).

:class:`DesignWatch` polls ``design_evaluations.jsonl`` (only the bytes added
since the last poll, up to the last complete line), ``design_checkpoint.json``
and ``result.json`` by size and modification time, and rebuilds the search's
progress (:func:`nlosplan.planner.design.progress.design_progress`) only when
something changed. It never writes into the folder.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

from nlosplan.errors import UserError
from nlosplan.planner.design.run import CHECKPOINT, EVALUATIONS

__all__ = ["DesignWatch", "is_design_folder"]

RESULT = "result.json"
#: Seconds of observed history the time-left estimate uses.
RATE_WINDOW_S = 600.0


def is_design_folder(path) -> bool:
    """Whether ``path`` is a design output folder (a run wrote its checkpoint or evaluation log there)."""
    p = Path(path)
    return p.is_dir() and ((p / CHECKPOINT).is_file() or (p / EVALUATIONS).is_file())


def _stat(path: Path):
    try:
        st = path.stat()
    except OSError:
        return None
    return (st.st_size, st.st_mtime_ns, st.st_ino)


class DesignWatch:
    """The state of a design run's files, refreshed on demand.

    Parameters
    ----------
    out : str or Path
        The design output folder.
    min_interval_s : float
        :meth:`refresh` reads the files at most this often (every page shares one watch).

    Attributes
    ----------
    version : int
        Increases whenever what the page shows changed.
    """

    def __init__(self, out, *, min_interval_s: float = 1.0):
        self.out = Path(out)  # may not hold the run's files yet (a run started with --live)
        self.min_interval_s = float(min_interval_s)
        self.version = 0
        self.results: list[dict] = []
        self.result: dict | None = None
        self.progress: dict | None = None
        self.progress_error: str | None = None
        self.label = ""
        self.config: dict = {}
        self._offset = 0
        self._log_inode = None
        self._stats: dict[str, object] = {}
        self._last_read = -math.inf
        self._landed: list[tuple[float, float]] = []   # (monotonic time seen, evaluation seconds) of new results
        self._first_seen: float | None = None
        self.last_change_utc: float | None = None

    # ------------------------------------------------------------------ reading
    def _read_log(self) -> bool:
        path = self.out / EVALUATIONS
        st = _stat(path)
        if st is None:
            changed = bool(self.results)
            self.results, self._offset = [], 0
            return changed
        size, _, inode = st
        if inode != self._log_inode or size < self._offset:  # a new run moved the old log to .bak
            self.results, self._offset, self._log_inode = [], 0, inode
            self._landed.clear()
        if size == self._offset:
            return False
        with open(path, "rb") as fh:
            fh.seek(self._offset)
            chunk = fh.read(size - self._offset)
        end = chunk.rfind(b"\n")
        if end < 0:
            return False  # only a line being written
        now = time.monotonic()
        fresh = 0
        for line in chunk[: end + 1].splitlines():
            try:
                rec = json.loads(line)
            except json.JSONDecodeError:  # a line torn by a killed run (the run ends it with a newline)
                continue
            self.results.append(rec)
            fresh += 1
            if self._first_seen is not None:
                self._landed.append((now, float(rec.get("seconds") or 0.0)))
        self._offset += end + 1
        return fresh > 0

    def _read_json(self, name: str):
        st = _stat(self.out / name)
        if st == self._stats.get(name):
            return False, None
        self._stats[name] = st
        if st is None:
            return True, None
        try:
            return True, json.loads((self.out / name).read_text())
        except (OSError, json.JSONDecodeError):  # being replaced: read again next time
            self._stats[name] = None
            return False, None

    def refresh(self, force: bool = False) -> bool:
        """Read what changed since the last call (at most every ``min_interval_s``); True if anything did."""
        now = time.monotonic()
        if not force and now - self._last_read < self.min_interval_s:
            return False
        self._last_read = now
        changed = self._read_log()
        ck_changed, ckpt = self._read_json(CHECKPOINT)
        if ck_changed and ckpt is not None:
            self.config = ckpt.get("config") or {}
            self.label = str(self.config.get("label", ""))
        res_changed, result = self._read_json(RESULT)
        if res_changed:
            self.result = result
        changed = changed or ck_changed or res_changed
        waiting = self.progress is not None and self.progress["stage"] == "references"  # files not in the log
        if changed or waiting or self.progress is None and self.progress_error is None:
            self._progress()
            self.version += 1
            self.last_change_utc = time.time()
        if self._first_seen is None:
            self._first_seen = now
        return changed

    def _progress(self) -> None:
        from nlosplan.planner.design.progress import design_progress

        try:
            self.progress = design_progress(self.out, self.results)
            self.progress_error = None
        except UserError as exc:
            self.progress, self.progress_error = None, str(exc)

    # ------------------------------------------------------------------ derived
    def answer(self) -> dict | None:
        """The answer to show: ``result.json`` once written, else the search's answer so far."""
        if self.result is not None and (self.progress is None or self.progress["finished"]):
            return self.result
        return None if self.progress is None else self.progress["summary"]

    def groups(self) -> list[dict]:
        """One entry per requirement of the run (its trade-off plot): ``name``, ``task``, ``condition``
        (``col=value`` or None), ``threshold``, ``metric``, ``smaller_is_better``; from the checkpoint's
        configuration, else (unreadable) one per task and condition in the log, without a threshold."""
        from nlosplan.planner.design.requirements import METRIC_OF_TASK, Requirement

        out = []
        try:
            for d in self.config.get("requirements") or []:
                r = Requirement.from_dict(d)
                out.append({"name": r.name, "task": r.task, "condition": None if r.condition is None
                            else str(r.condition), "threshold": r.threshold, "metric": r.metric,
                            "smaller_is_better": r.smaller_is_better})
        except (UserError, KeyError, TypeError, ValueError):
            out = []
        if out:
            return out
        for task, cond in dict.fromkeys((r.get("task"), r.get("condition")) for r in self.results):
            metric, smaller, _ = METRIC_OF_TASK.get(task, (str(task), True, ""))
            out.append({"name": f"{task}{' [' + cond + ']' if cond else ''}", "task": task, "condition": cond,
                        "threshold": None, "metric": metric, "smaller_is_better": smaller})
        return out

    def seconds_left(self) -> float | None:
        """Time left in the current stage, s: its evaluations left at each evaluator's median run time,
        divided by the parallelism seen (evaluation seconds landed per wall second); None before any
        evaluation has landed while this watch looked, or when nothing is left."""
        if self.progress is None or not self.progress["left"]:
            return None
        now = time.monotonic()
        recent = [(t, s) for t, s in self._landed if now - t <= RATE_WINDOW_S]
        if len(recent) < 2 or self._first_seen is None:
            return None
        wall = now - max(self._first_seen, now - RATE_WINDOW_S)
        parallel = sum(s for _, s in recent) / wall if wall > 0 else 0.0
        if parallel <= 0:
            return None
        need = 0.0
        for ev, n in self.progress["left_by_evaluator"].items():
            secs = sorted(float(r["seconds"]) for r in self.results if r.get("evaluator") == ev and r.get("seconds"))
            if not secs:
                return None
            need += n * secs[len(secs) // 2]
        return need / parallel

    def seconds_since_last(self) -> float | None:
        """Seconds since the evaluation log last changed (its modification time)."""
        st = _stat(self.out / EVALUATIONS)
        return None if st is None else max(0.0, time.time() - st[1] / 1e9)

    def evaluators(self) -> list[dict]:
        """Per evaluation: evaluator, task, run time and interval half-width (the error-vs-run-time points)."""
        rows = []
        for r in self.results:
            lo, hi, v = r.get("lo"), r.get("hi"), r.get("value")
            ok = r.get("status") == "ok" and all(isinstance(x, (int, float)) and math.isfinite(x) for x in (lo, hi, v))
            rows.append({"evaluator": r.get("evaluator"), "task": r.get("task"), "seconds": r.get("seconds"),
                         "half": 0.5 * (hi - lo) if ok else None, "value": v if ok else None,
                         "design": _design_key(r.get("design")), "status": r.get("status")})
        return rows


def _design_key(d) -> str:
    if not isinstance(d, dict):
        return str(d)
    from nlosplan.planner.design.space import Design

    try:
        return Design.from_dict(d).key()
    except (TypeError, ValueError, KeyError):
        return json.dumps(d, sort_keys=True)

