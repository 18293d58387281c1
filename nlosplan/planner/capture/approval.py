"""The approval gate's files: a proposed batch waits for one answer, from the terminal or from the live page.

``rig run --approve`` asks a person before each batch moves the gantry. The
question and the answers are files in the run's output folder, so any
process that can write there can answer (the terminal prompt of the run
itself, or the live page of ``nlosplan serve``/``--live``), and the first
answer wins:

``approval.json``
    The current request, rewritten atomically: ``request_id`` (new for every
    question), ``run_id``, ``batch`` (0, 1, ...), ``ids`` (the proposals in
    route order), ``budget_left``, ``status`` (``"pending"`` or
    ``"answered"``), and once answered ``decision``, ``drop``, ``add``,
    ``answered_by`` and ``note``.
``approval_answer_<request_id>.json``
    The answer, created exclusively (a complete temporary file hard-linked to
    its name: it appears whole, and a second answer to the same request
    fails): ``decision`` (``"approve"`` or ``"refuse"``), ``drop`` (proposal
    ids), ``add`` (candidate indices), ``by``.
``approvals.jsonl``
    Every request with its outcome, one line each (what was asked, what was
    answered, by whom).

An answer to another request id (a stale file of an earlier run in the same
folder) is never taken. A rerun of the same run (which resumes from the store
and, the planner being deterministic, proposes the same batches) finds the
approvals it was given in ``approvals.jsonl`` (:func:`given_approval`), so
the batches it runs again are the ones approved, edits included; a refusal is
never replayed (rerunning is how a refused run goes on).
"""

from __future__ import annotations

import json
import os
import uuid
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from pathlib import Path

from nlosplan.errors import UserError

__all__ = ["REQUEST", "LOG", "Answer", "answer_path", "close_request", "given_approval", "post_request", "read_answer",
           "read_request", "submit_answer"]

REQUEST = "approval.json"
LOG = "approvals.jsonl"
FORMAT = "nlosplan-approval/1"
DECISIONS = ("approve", "refuse")


def _utc() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


@dataclass(frozen=True)
class Answer:
    """One answer to a proposed batch.

    Attributes
    ----------
    decision : {"approve", "refuse"}
    drop : tuple of str
        Proposal ids not to capture (with ``approve``).
    add : tuple of int
        Candidate indices to capture as well (with ``approve``).
    by : str
        Who answered: ``"terminal"`` or ``"page"``.
    """

    decision: str
    drop: tuple = field(default_factory=tuple)
    add: tuple = field(default_factory=tuple)
    by: str = "terminal"

    def __post_init__(self) -> None:
        if self.decision not in DECISIONS:
            raise UserError(f"approval decision {self.decision!r}; allowed: {', '.join(DECISIONS)}")
        object.__setattr__(self, "drop", tuple(str(v) for v in self.drop))
        object.__setattr__(self, "add", tuple(int(v) for v in self.add))
        if self.decision == "refuse" and (self.drop or self.add):
            raise UserError("a refused batch has nothing to drop or add")

    @property
    def edited(self) -> bool:
        """Whether the batch was changed (positions dropped or added)."""
        return bool(self.drop or self.add)

    def to_dict(self) -> dict:
        return {**asdict(self), "drop": list(self.drop), "add": list(self.add)}


def _write(path: Path, data: dict) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(data), encoding="utf-8")
    os.replace(tmp, path)


def answer_path(out, request_id: str) -> Path:
    """The answer file of a request."""
    return Path(out) / f"approval_answer_{request_id}.json"


def post_request(out, *, run_id: str, batch: int, ids, positions=None, budget_left: int | None = None) -> dict:
    """Ask for an answer to a proposed batch: write ``approval.json`` (status pending) and return it.

    ``positions`` are the batch's (x_mm, y_mm) in route order (kept with the request and its log line).
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    req = {"format": FORMAT, "request_id": uuid.uuid4().hex[:16], "run_id": run_id, "batch": int(batch),
           "ids": [str(i) for i in ids], "positions": None if positions is None else [[round(float(v), 4) for v in p]
                                                                                     for p in positions],
           "budget_left": budget_left, "status": "pending", "pid": os.getpid(), "created_utc": _utc()}
    _write(out / REQUEST, req)
    return req


def read_request(out) -> dict | None:
    """The current request (None when there is none or it cannot be read yet)."""
    try:
        req = json.loads((Path(out) / REQUEST).read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError):
        return None
    return req if isinstance(req, dict) and req.get("format") == FORMAT else None


def submit_answer(out, request_id: str, answer: Answer) -> bool:
    """Answer a pending request; False when it was answered first by someone else (or is not pending).

    Raises
    ------
    UserError
        No such request is pending in ``out``.
    """
    req = read_request(out)
    if req is None or req.get("request_id") != request_id:
        raise UserError(f"no batch awaits approval under request {request_id!r} in {out}")
    if req.get("status") != "pending":
        return False
    target = answer_path(out, request_id)
    tmp = target.with_name(f".{target.name}.{os.getpid()}.{uuid.uuid4().hex[:6]}.tmp")
    tmp.write_text(json.dumps({"request_id": request_id, **answer.to_dict(), "answered_utc": _utc()}),
                   encoding="utf-8")
    try:
        os.link(tmp, target)  # exclusive and whole: the first answer wins
        return True
    except FileExistsError:
        return False
    finally:
        tmp.unlink(missing_ok=True)


def read_answer(out, request_id: str) -> Answer | None:
    """The answer to a request, once given (None before)."""
    try:
        data = json.loads(answer_path(out, request_id).read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError):
        return None
    if data.get("request_id") != request_id:
        return None
    return Answer(data["decision"], tuple(data.get("drop", ())), tuple(data.get("add", ())), data.get("by", "?"))


def close_request(out, request: dict, answer: Answer, note: str = "") -> dict:
    """Mark a request answered (``approval.json``), log it (``approvals.jsonl``) and remove its answer file."""
    out = Path(out)
    done = {**request, "status": "answered", "decision": answer.decision, "drop": list(answer.drop),
            "add": list(answer.add), "answered_by": answer.by, "answered_utc": _utc(), "note": note}
    _write(out / REQUEST, done)
    with open(out / LOG, "a", encoding="utf-8") as fh:
        fh.write(json.dumps(done) + "\n")
    answer_path(out, request["request_id"]).unlink(missing_ok=True)
    return done


def given_approval(out, run_id: str, batch: int, ids, positions) -> dict | None:
    """The approval (approve, edited or not) an earlier run of ``run_id`` got for this batch with these
    proposal ids at these positions, from ``approvals.jsonl`` (the last one; an edit that could not run
    does not count); None when there is none."""
    where = [[round(float(v), 4) for v in p] for p in positions]
    path = Path(out) / LOG
    found = None
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except OSError:
        return None
    for line in lines:
        try:
            rec = json.loads(line)
        except json.JSONDecodeError:
            continue
        if (rec.get("run_id") == run_id and rec.get("batch") == int(batch) and rec.get("ids") == [str(i) for i in ids]
                and rec.get("positions") == where and rec.get("decision") == "approve"
                and not str(rec.get("note", "")).startswith("not run")):
            found = rec
    return found
