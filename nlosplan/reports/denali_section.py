"""The design report's first section, the answer at DENALI's own design point, and the evaluators' consistency.

Both read what :func:`nlosplan.planner.design.summary.summarize` put in the result (``denali_point``,
``consistency``; :mod:`nlosplan.planner.design.denali_point` computes them) and compute nothing: tables as
:class:`pandas.DataFrame` of strings (the report escapes them in the HTML) and the sentences around them.
"""

from __future__ import annotations

import pandas as pd

__all__ = ["DENALI_TITLE", "CONSISTENCY_TITLE", "denali_point_table", "denali_point_text", "disagreement_text",
           "consistency_table", "consistency_text", "answer_note", "trained_verdict", "budget_text", "curve_text"]

DENALI_TITLE = "At DENALI's own design point"
CONSISTENCY_TITLE = "Evaluator consistency: learners against their bounds"
#: DENALI's recipe as its paper trained it (Table 1): what the run's learners are set against.
DENALI_RECIPE = "DENALI's 1D CNN on 25,200 real captures for 60-100 epochs"


def _fmt(task: str, v) -> str:
    if v is None:
        return "n/a"
    return f"{100 * v:.1f} cm" if task == "loc" else f"{100 * v:.1f} %"


def _interval(task: str, value, interval) -> str:
    if value is None:
        return "not trained"
    if not interval or None in interval:
        return _fmt(task, value)
    return f"{_fmt(task, value)} [{_fmt(task, interval[0])}, {_fmt(task, interval[1])}]"


def _captures(n) -> str:
    return "?" if n is None else f"{n:,}"


def trained_verdict(row: dict) -> str:
    """A ``denali_point`` row's verdict with what it is about: "met with an MLP trained on 2,100 captures"."""
    from nlosplan.tasks.names import model_phrase

    if row["verdict"] is None:
        return "not evaluated"
    n = row["train_captures"]
    return f"{row['verdict']} with {model_phrase(row['learner'])} trained on {_captures(n)} captures"


def budget_text(summary: dict) -> str:
    """One sentence: the run's training budget and learner family (``result.json``'s ``train_captures``)."""
    from nlosplan.tasks.names import model_phrase

    b = summary.get("train_captures")
    if not b:
        return ""
    label = lambda m: model_phrase(m).split(" ", 1)[1]  # noqa: E731
    learners = ", ".join(f"{task} {label(m)}" for task, m in b["learner"].items())
    sets = "; --train-captures N sets it" if b["default"] else ""
    return (f"Training budget: {b['requested']:,} {b['captures']} training captures per learner at a design "
            f"({b['rule']}{sets}), at most {b['epochs']} epochs; learners {learners} (the best of "
            f"{', '.join(map(label, b['models']))} on the reference design).")


def _curve_point(task: str, c: dict) -> str:
    own = " (the run's budget)" if c["run_budget"] else ""
    return f"{c['train_captures']:,}{own} {_fmt(task, c['value'])}"


def curve_text(summary: dict) -> str:
    """The learners' learning curves at the reference design, one clause per requirement, and what they say of the
    run's verdicts (``denali_point``'s ``learning_curve``, ``run_budget``, ``conservative``)."""
    rows = [r for r in summary.get("denali_point", []) if r.get("learning_curve")]
    if not rows:
        return ""
    parts = []
    for r in rows:
        task = r["task"]
        pts = ", ".join(_curve_point(task, c) for c in r["learning_curve"])
        parts.append(f"{r['requirement']} ({r['learner']}): {pts}")
    own = next((r["run_budget"]["train_captures"] for r in rows if r.get("run_budget")), None)
    text = ("Learning curves at this design (training captures: the learner's mean over its seeds; every point "
            "trained, none extrapolated): " + "; ".join(parts) + ".")
    at = [r for r in rows if r["evaluator"] == "learning_curve"]
    if at:
        text += (f" The prediction above is the learner trained on {at[0]['train_captures']:,} captures, DENALI's "
                 "Table 1 budget.")
    if own is not None:
        worse = [r["requirement"] for r in rows if r.get("conservative") is False]
        if worse:
            text += (f" More captures made the learner worse for {', '.join(worse)} on this curve: the run's "
                     f"verdicts, made at {own:,} captures per design, may promise more than DENALI's budget gives.")
        elif any(r.get("conservative") for r in rows):
            text += (f" Every other design is judged with {own:,} captures; here the largest budget leaves the "
                     "learner no worse (within its interval), so those verdicts look conservative: a design met with "
                     f"{own:,} captures would be met with DENALI's, and one not met might be met with more captures "
                     "(not examined at other designs).")
    return text


def denali_point_table(summary: dict) -> pd.DataFrame:
    """One row per requirement: the run's prediction at DENALI's design, its bound, DENALI's real figure, verdicts."""
    rows = []
    for r in summary.get("denali_point", []):
        task = r["task"]
        agrees = r["agrees"]
        rows.append({"requirement": r["requirement"],
                     "predicted [95 % interval]": _interval(task, r["predicted"], r["interval"]),
                     "learner": (f"{r['learner']}, {_captures(r['train_captures'])} {r['captures']} training "
                                 f"captures, {r['seeds']} seed(s)"),
                     "bound": (f"{_fmt(task, r['bound'])} ({r['bound_name']})" if r["bound"] is not None
                                else f"n/a ({r['bound_name']})"),
                     "verdict": trained_verdict(r),
                     "DENALI real": _fmt(task, r["real"]), "real verdict": r["real_verdict"] or "n/a",
                     "agrees": "n/a" if agrees is None else ("yes" if agrees else "NO")})
    return pd.DataFrame(rows, columns=["requirement", "predicted [95 % interval]", "learner", "bound", "verdict",
                                       "DENALI real", "real verdict", "agrees"])


def _names(rows: list[dict]) -> str:
    return ", ".join(f"{r['requirement']} ({r['verdict'] or 'not evaluated'}, real {r['real_verdict']})"
                     for r in rows)


def disagreement_text(summary: dict) -> str:
    """One plain sentence per kind of disagreement between a verdict at DENALI's design and DENALI's real one."""
    rows = [r for r in summary.get("denali_point", []) if r["agrees"] is False]
    wide = [r for r in rows if r["verdict"] == "undecided" and r["real_in_interval"]]
    harder = [r for r in rows if r["real_verdict"] == "met" and r not in wide]
    easier = [r for r in rows if r["real_verdict"] != "met" and r not in wide]
    out = []
    if harder:
        n = max((r["train_captures"] or 0 for r in harder), default=0)
        budget = f"trained on {n:,} captures" if n else "trained here"
        room = [r for r in harder if not r.get("real_beats_bound")]
        text = (f"At DENALI's design this run's verdicts disagree with reality for {_names(harder)}: DENALI's "
                "hardware meets them.")
        if room:
            text += (f" For {', '.join(r['requirement'] for r in room)} this world's own bound reaches DENALI's real "
                     f"figure, so the shortfall is the learner's ({budget}, against {DENALI_RECIPE}), not the "
                     "world's alone: `nlosplan bench denali` runs DENALI's recipe and the neighbours on this world "
                     "under DENALI's protocol beside Table 1.")
        out.append(text)
    if easier:
        out.append(f"At DENALI's design this run is more optimistic than reality for {_names(easier)}: DENALI's "
                   "measured figure does not meet them, so the simulated world or its learner promises more than "
                   "the real rig gave (`nlosplan bench denali` sets DENALI's recipe on simulated captures beside "
                   "Table 1).")
    if wide:
        out.append(f"Undecided where DENALI's real figure lies inside the predicted interval for {_names(wide)}: the "
                   "prediction does not contradict reality, its interval is too wide to decide (more seeds, or a "
                   "learner that varies less between runs, would).")
    beyond = [r for r in summary.get("denali_point", []) if r.get("real_beats_bound")]
    if beyond:
        out.append("DENALI's real figure lies beyond this world's own bound at the same design for "
                   + ", ".join(f"{r['requirement']} ({_fmt(r['task'], r['real'])} against the {r['bound_name']}'s "
                               f"{_fmt(r['task'], r['bound'])})" for r in beyond)
                   + ": even the bound of this world falls short of reality there, so the simulated world is harder "
                     "than the real one.")
    return " ".join(out)


def denali_point_text(summary: dict) -> str:
    """The section's lead: what is compared, and the sentence where the verdicts disagree with reality."""
    rows = summary.get("denali_point", [])
    if not rows:
        return "No requirement was evaluated at the reference design."
    if not all(r["denali_design"] for r in rows):
        return (f"The reference design ({summary['reference_sensor']}) is not DENALI's TMF8828 (3x3, 128 bins of "
                "92.8 ps): DENALI's real figures are shown, not compared.")
    lead = ("DENALI's own sensor (3x3 zones, 128 bins of 92.8 ps, no added jitter, all its photons) in this run's "
            "simulated world, predicted by each task's learner (the mean of its seeds with the 95 % interval) and "
            f"bounded by the task's bound, beside DENALI's measured Table 1 ({DENALI_RECIPE}); a real figure "
            "judged against the same requirement.")
    agree = "" if any(r["agrees"] is False for r in rows) else "Every verdict here agrees with DENALI's real result."
    short = [f"{r['requirement']}: {r['train_note']}" for r in rows if r.get("train_note")]
    fewer = f"Fewer training captures than asked: {'; '.join(short)}." if short else ""
    return " ".join(t for t in (lead, budget_text(summary), curve_text(summary), agree, fewer,
                                disagreement_text(summary)) if t)


def answer_note(summary: dict, requirement: str) -> str:
    """The sentence beside a requirement's answer when it needs more than DENALI's hardware (empty otherwise)."""
    return next((r["answer_note"] for r in summary.get("denali_point", []) if r["requirement"] == requirement), "")


def consistency_table(summary: dict) -> pd.DataFrame:
    """One row per learner figure that beats its bound beyond its interval."""
    rows = []
    for c in summary.get("consistency", []):
        task = c["task"]
        rows.append({"requirement": c["requirement"], "design": c["design"], "learner": c["learner"],
                     "learner figure [95 % interval]": _interval(task, c["value"], [c["lo"], c["hi"]]),
                     "bound": f"{_fmt(task, c['bound'])} ({c['bound_name']})", "inconsistent": c["issue"]})
    return pd.DataFrame(rows, columns=["requirement", "design", "learner", "learner figure [95 % interval]", "bound",
                                       "inconsistent"])


def consistency_text(summary: dict) -> str:
    """The consistency section's sentence: consistent, or how many figures beat their bound and what that means."""
    flagged = summary.get("consistency", [])
    if not flagged:
        return ("The three evaluators are consistent: no trained learner's 95 % interval lies beyond its task's bound "
                "(the Cramér–Rao bound for localization, the ideal observer for shape and size) at any design.")
    return (f"{len(flagged)} learner figure(s) beat their task's bound beyond their 95 % interval, which a correct "
            "bound forbids: the bound is computed on its own scenes (a subset of objects and positions), and the "
            "Cramér–Rao bound holds for unbiased estimators only (a learner drawn toward the gantry's centre can "
            "beat it where the bound is near chance); these figures need a look before they are trusted."
            + _session_reading(summary, flagged))


def _session_reading(summary: dict, flagged: list) -> str:
    """Why a class learner can pass the ideal observer in a world with capture sessions (empty otherwise)."""
    sd = (summary.get("world_model") or {}).get("session_floor_sd") or 0.0
    if not sd or not any(c.get("bound_name") == "ideal observer" for c in flagged):
        return ""
    return (f" Here the simulated captures come in capture sessions (every object, size and lighting with its own "
            f"floor, spread {100 * sd:.2f} %) and the ideal observer does not see them: a learner that tells the "
            "sessions apart tells the classes apart with them, since every session has captures on both sides of the "
            "split. DENALI's real 1D CNN reads its captures the same way (shape 38.8 % on DENALI's split, 4.2 % on a "
            "size it never saw): a class figure above the observer measures that reading, not what the sensor tells "
            "of the shape.")
