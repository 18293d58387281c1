"""What a rig run has captured and what is left, read back from the store."""

from __future__ import annotations

from nlosplan.hardware.commands import Capture, CaptureResult, Move

__all__ = ["plan_from_spec", "plan_steps", "run_status", "runs"]


def plan_from_spec(spec: dict):
    """Rebuild a built-in plan from the ``plan_spec`` a run stored (None for other plans)."""
    from nlosplan.hardware.plans import positions_plan, raster_plan

    kind = (spec or {}).get("kind")
    if kind == "raster":
        return raster_plan(repeats=spec["repeats"], settle_s=spec.get("settle_s", 0.0), positions=spec["positions"])
    if kind == "positions":
        return positions_plan([tuple(p) for p in spec["points"]], repeats=spec["repeats"],
                              settle_s=spec.get("settle_s", 0.0))
    return None


def plan_steps(plan) -> list[tuple[int, float, float, int]]:
    """(step, x_mm, y_mm, repeat) of every capture of a plan, run dry."""
    out, target, reply = [], None, None
    while True:
        try:
            cmd = plan.send(reply)
        except StopIteration:
            return out
        reply = None
        if isinstance(cmd, Move):
            target = (cmd.x_mm, cmd.y_mm)
        elif isinstance(cmd, Capture):
            step = len(out)
            out.append((step, target[0], target[1], cmd.repeat))
            reply = CaptureResult(step, cmd.repeat, None, None, None, target, None, None, dry=True)


def runs(store) -> dict[str, list]:
    """Captures of every rig run in the store: ``{run_id: [Capture, ...]}`` (ordered by id)."""
    from nlosplan.errors import UserError

    out: dict[str, list] = {}
    for cap in store.iter_captures():
        rid, step = cap.meta.get("run_id"), cap.meta.get("step")
        if rid is None or step is None:
            continue
        if not isinstance(rid, str) or isinstance(step, bool) or not isinstance(step, int) or step < 0:
            raise UserError(f"capture {cap.id} of capture store {store.path} is damaged: its run id or step "
                            f"({str(rid)[:40]!r}, {str(step)[:20]!r}) is not a name and a step number")
        out.setdefault(rid, []).append(cap)
    return out


def run_status(store, run_id: str | None = None, show_missing: int = 10) -> list[dict]:
    """Per run: captures stored, planned, left, the last capture, and the first missing steps.

    Returns
    -------
    list of dict
        ``run_id``, ``plan``, ``captured``, ``planned`` (None when unknown),
        ``left``, ``positions`` (distinct commanded positions), ``last_utc``,
        ``last_step``, ``missing`` (up to ``show_missing`` (step, x_mm, y_mm,
        repeat) when the plan can be rebuilt), ``source``, ``object``, ``lights``.
    """
    from nlosplan.errors import UserError

    found = runs(store)
    if run_id is not None:
        if run_id not in found:
            raise UserError(f"no run {run_id!r} in {store.path}; runs: {', '.join(sorted(found)) or 'none'}")
        found = {run_id: found[run_id]}
    out = []
    for rid, caps in sorted(found.items()):
        steps = {int(c.meta["step"]) for c in caps}
        planned = caps[-1].meta.get("plan_total")
        spec = next((c.meta["plan_spec"] for c in caps if "plan_spec" in c.meta), None)
        missing = []
        try:
            plan = plan_from_spec(spec) if spec else None
        except (KeyError, TypeError, ValueError, AttributeError):   # a plan_spec edited or damaged
            raise UserError(f"run {rid!r} in {store.path}: its stored plan_spec cannot be read back") from None
        if plan is not None:
            todo = [s for s in plan_steps(plan) if s[0] not in steps]
            planned = planned or len(steps) + len(todo)
            missing = [{"step": s, "x_mm": round(x, 3), "y_mm": round(y, 3), "repeat": r}
                       for s, x, y, r in todo[:show_missing]]
        last = caps[-1]
        out.append({
            "run_id": rid, "plan": last.meta.get("plan", ""), "captured": len(steps), "planned": planned,
            "left": None if planned is None else max(planned - len(steps), 0),
            "positions": len({tuple(c.meta.get("commanded_mm") or ()) for c in caps}),
            "last_utc": last.meta.get("t_capture_end_utc"), "last_step": int(last.meta["step"]),
            "missing": missing, "source": last.labels["source"], "object": f"{last.labels['object']} "
            f"{last.labels['size']}", "lights": sorted({c.labels["lights"] for c in caps}),
        })
    return out
