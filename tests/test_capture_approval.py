"""The approval gate: editing a pending batch (amend), the answer files (first answer wins), the closed loop's
checkpoint with the pending batch and its history (what the live page reads)."""

import json
import threading

import numpy as np
import pytest

from nlosplan.errors import UserError
from nlosplan.planner.capture import CapturePlanner, PlannerConfig
from nlosplan.planner.capture.approval import (LOG, REQUEST, Answer, answer_path, close_request, post_request,
                                               read_answer, read_request, submit_answer)
from nlosplan.planner.capture.closed_loop import ClosedLoop
from test_capture_planner import observe, synthetic_space


def planner(budget=6, batch=2, strategy="random"):
    space = synthetic_space()
    return space, CapturePlanner(space, PlannerConfig(strategy=strategy, batch_size=batch, budget=budget, seed=1))


def test_amend_drops_and_adds_free_candidates_in_route_order():
    space, p = planner()
    batch = p.suggest()
    ids = [b["id"] for b in batch]
    taken = {b["index"] for b in batch}
    free = [i for i in range(space.size) if i not in taken][:2]
    edited = p.amend(ids, drop=[ids[0]], add=free)
    assert {e["index"] for e in edited} == {batch[1]["index"], *free}
    assert p.proposals[ids[0]]["status"] == "dropped"
    assert [e["batch_order"] for e in edited] == [0, 1, 2]
    # the route from the gantry is no longer than the edited batch in any other order
    from nlosplan.planner.capture.route import path_cost, _costs

    pts = np.array([[e["x_mm"], e["y_mm"]] for e in edited])
    cost = _costs(p.position_mm, pts, p.config.motion)
    import itertools

    best = min(path_cost(np.array(o) + 1, cost) for o in itertools.permutations(range(len(pts))))
    assert path_cost(np.arange(len(pts)) + 1, cost) == pytest.approx(best)
    # ingesting the edited batch: the added ones are observations, the dropped one is free again
    rng = np.random.default_rng(0)
    p.ingest([{"id": e["id"], "histogram": observe(space, e["index"], rng)} for e in edited])
    assert sorted(p.captured.tolist()) == sorted(e["index"] for e in edited)
    assert p._allowed()[batch[0]["index"]]
    state = json.loads(json.dumps(p.state_dict()))
    assert [q["status"] for q in state["proposals"]].count("dropped") == 1


def test_amend_refuses_what_cannot_run():
    space, p = planner(budget=3, batch=2)
    batch = p.suggest()
    ids = [b["id"] for b in batch]
    free = [i for i in range(space.size) if i not in {b["index"] for b in batch}]
    with pytest.raises(UserError, match="not in the batch"):
        p.amend(ids, drop=["c09999"])
    with pytest.raises(UserError, match="is not free"):
        p.amend(ids, add=[batch[0]["index"]])
    with pytest.raises(UserError, match="does not exist"):
        p.amend(ids, add=[space.size])
    with pytest.raises(UserError, match="budget leaves room for 1 more"):
        p.amend(ids, add=free[:2])
    with pytest.raises(UserError, match="empty"):
        p.amend(ids, drop=ids)
    assert p.amend(ids, drop=[ids[0]], add=free[:2], check_only=True) == []
    assert all(p.proposals[i]["status"] == "pending" for i in ids)  # a check changes nothing
    assert len(p.amend(ids, drop=[ids[0]], add=free[:2])) == 3       # one dropped makes room for two


def test_checkpoint_has_candidates_keepout_and_the_pending_batch(tmp_path):
    space, p = planner()
    space.excluded.append({"x_mm": 999.0, "y_mm": 0.0, "reason": "outside the gantry limits"})
    loop = ClosedLoop(p, checkpoint=tmp_path / "planner.json", target_rmse_m=0.01)
    pts = loop.suggest(2)
    state = json.loads((tmp_path / "planner.json").read_text())
    assert np.allclose(state["space"]["points_mm"], space.points_mm)
    assert state["space"]["excluded"][-1]["reason"] == "outside the gantry limits"
    pending = [q for q in state["proposals"] if q["status"] == "pending"]
    assert [(q["x_mm"], q["y_mm"]) for q in sorted(pending, key=lambda q: q["batch_order"])] == pts
    assert state["loop"] == {"target_rmse_m": 0.01, "history": []}
    assert CapturePlanner.from_state(state, space).proposals.keys() == p.proposals.keys()


def test_closed_loop_runs_an_edited_batch():
    space, p = planner()
    seen = {}

    def approve(batch, pl):
        seen["batch"] = batch
        free = next(i for i in range(space.size) if i not in {b["index"] for b in batch})
        seen["added"] = free
        return {"drop": [batch[0]["id"]], "add": [free]}

    loop = ClosedLoop(p, approve=approve)
    pts = loop.suggest(2)
    want = {tuple(space.points_mm[seen["added"]]), (seen["batch"][1]["x_mm"], seen["batch"][1]["y_mm"])}
    assert set(pts) == want and len(pts) == 2


def test_the_first_answer_wins_and_stale_answers_are_ignored(tmp_path):
    old = post_request(tmp_path, run_id="r", batch=0, ids=["c00000"])
    assert submit_answer(tmp_path, old["request_id"], Answer("approve", by="page"))
    req = post_request(tmp_path, run_id="r", batch=0, ids=["c00000", "c00001"], budget_left=3)
    assert read_request(tmp_path)["status"] == "pending"
    assert read_answer(tmp_path, req["request_id"]) is None   # the old request's answer is not this one's
    results = []
    barrier = threading.Barrier(8)

    def answer(k):
        barrier.wait()
        a = Answer("approve", drop=["c00001"], by="page") if k % 2 else Answer("refuse", by="terminal")
        results.append((k, submit_answer(tmp_path, req["request_id"], a)))

    threads = [threading.Thread(target=answer, args=(k,)) for k in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    winners = [k for k, ok in results if ok]
    assert len(winners) == 1
    got = read_answer(tmp_path, req["request_id"])
    assert got.by == ("page" if winners[0] % 2 else "terminal")
    done = close_request(tmp_path, req, got)
    assert read_request(tmp_path)["status"] == "answered" and done["answered_by"] == got.by
    assert not answer_path(tmp_path, req["request_id"]).exists()
    assert not submit_answer(tmp_path, req["request_id"], Answer("approve"))   # answered: nothing more is taken
    log = [json.loads(line) for line in (tmp_path / LOG).read_text().splitlines()]
    assert [r["request_id"] for r in log] == [req["request_id"]]
    with pytest.raises(UserError, match="no batch awaits approval"):
        submit_answer(tmp_path, "nope", Answer("approve"))
    assert (tmp_path / REQUEST).exists()


def test_answers_are_checked():
    with pytest.raises(UserError, match="allowed: approve, refuse"):
        Answer("maybe")
    with pytest.raises(UserError, match="nothing to drop"):
        Answer("refuse", drop=["c00000"])
    assert Answer("approve", add=[3]).edited and not Answer("approve").edited


def test_a_rerun_finds_the_approvals_given_but_never_a_refusal(tmp_path):
    from nlosplan.planner.capture.approval import given_approval

    where = [(320.0, 0.0), (320.0, 80.0)]
    req = post_request(tmp_path, run_id="r", batch=0, ids=["c00000", "c00001"], positions=where)
    submit_answer(tmp_path, req["request_id"], Answer("approve", drop=["c00001"], add=[7], by="page"))
    close_request(tmp_path, req, read_answer(tmp_path, req["request_id"]))
    req = post_request(tmp_path, run_id="r", batch=1, ids=["c00003"], positions=[(0.0, 0.0)])
    close_request(tmp_path, req, Answer("refuse"))
    req = post_request(tmp_path, run_id="r", batch=2, ids=["c00004"], positions=[(0.0, 80.0)])
    close_request(tmp_path, req, Answer("approve", add=[99], by="page"), note="not run: candidate 99 does not exist")
    got = given_approval(tmp_path, "r", 0, ["c00000", "c00001"], where)
    assert (got["drop"], got["add"], got["answered_by"]) == (["c00001"], [7], "page")
    assert given_approval(tmp_path, "r", 1, ["c00003"], [(0.0, 0.0)]) is None           # refused: asked again
    assert given_approval(tmp_path, "r", 2, ["c00004"], [(0.0, 80.0)]) is None          # an edit that did not run
    assert given_approval(tmp_path, "other", 0, ["c00000", "c00001"], where) is None    # another run
    assert given_approval(tmp_path, "r", 0, ["c00000", "c00001"], [(0.0, 0.0), (320.0, 80.0)]) is None  # elsewhere
