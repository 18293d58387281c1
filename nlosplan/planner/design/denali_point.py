"""The answer at DENALI's own design point, beside DENALI's real result, and the evaluators' consistency.

DENALI's design point is the space's reference design when the reference sensor has DENALI's TMF8828 geometry
(3x3 zones, 128 bins of 92.8 ps, no added jitter or pulse, all its photons): the design every learner is first
trained on, and every one-at-a-time line starts from. There the run already has, per requirement, the task's
learner's runs and its bound (Cramér–Rao for localization, the ideal observer for the classes); DENALI's paper
measured the same sensor on the real rig (Table 1, :func:`nlosplan.tasks.denali_protocol.table1`). A row sets the
two side by side (:func:`point_row`): the predicted metric with its 95 % interval and verdict, the real figure and
the verdict it gives against the same requirement, and whether the two verdicts agree. The real figure is the best
model of Table 1 for the task's metric (DENALI's 1D CNN for all three tasks), overall rows only: a requirement
under a condition has no real figure.

Where DENALI's real figure meets a requirement, the run's least hardware should be no more than DENALI's: an
answer that costs more than the reference design, or none met, gets one sentence saying so
(:func:`answer_note`).

Consistency (:func:`bound_conflict`): a bound is the best any estimator can do on the task (the Cramér–Rao bound:
any unbiased one), so a learner whose whole 95 % interval lies beyond its design's bound is flagged. Metres for
``loc_rmse``, fractions for accuracies, as everywhere in ``result.json``.
"""

from __future__ import annotations

import math

from nlosplan.planner.design.budget import TRAIN_NOTE
from nlosplan.planner.design.evaluation import Evaluator
from nlosplan.planner.design.evidence import Evidence
from nlosplan.planner.design.learning_curve import (DENALI_TRAIN_CAPTURES, curve_estimates, curve_rows,
                                                    curve_summary, run_budget)
from nlosplan.planner.design.requirements import Requirement
from nlosplan.planner.design.space import Design
from nlosplan.planner.design.verdicts import MET, NOT_MET, Estimate, seed_interval

__all__ = ["real_figure", "point_row", "denali_point", "answer_note", "bound_conflict", "consistency",
           "BOUND_NAMES", "is_denali_design"]

#: The bound of each kind of task, as the report names it.
BOUND_NAMES = {True: "Cramér–Rao bound", False: "ideal observer"}


def _num(v: float | None) -> float | None:
    """A finite float, else None (JSON carries no NaN or infinity here)."""
    return float(v) if v is not None and math.isfinite(v) else None


def _fmt(req: Requirement, v: float) -> str:
    return f"{100 * v:.1f} cm" if req.smaller_is_better else f"{100 * v:.1f} %"


def real_figure(req: Requirement) -> tuple[float | None, str]:
    """DENALI's real figure for ``req`` (the best model of Table 1 on its metric) and where it comes from.

    Returns
    -------
    value : float or None
        ``loc_rmse`` in metres or a top-1 accuracy; None under a condition (Table 1 has overall rows only) or
        where Table 1 has no figure for the metric.
    source : str
        One line: the table, the model and what it was trained on, or why there is no figure.
    """
    from nlosplan.tasks.denali_protocol import table1

    if req.condition is not None:
        return None, f"DENALI's Table 1 gives overall figures only, none under {req.condition}"
    models = table1()["values"].get(req.task.value, {})
    figures = {m: float(v[req.metric]) for m, v in models.items() if req.metric in v}
    if not figures:
        return None, f"DENALI's Table 1 has no {req.metric} for {req.task}"
    best = (min if req.smaller_is_better else max)(figures, key=figures.get)
    return figures[best], (f"DENALI Table 1 (real captures of DENALI's TMF8828 3x3 on DENALI's rig), {best} trained "
                           f"on 25,200 real captures; the best of {', '.join(figures)}")


def is_denali_design(d: Design, sensor) -> bool:
    """Whether ``d`` on the reference ``sensor`` is DENALI's TMF8828: 3x3, its bins and bin width, no added blur,
    all the photons (the DENALI-calibrated preset's geometry; the world it is simulated in is another matter)."""
    from nlosplan.sensor_models import resolve_sensor
    from nlosplan.simulators.presets.scene_model import DEFAULT_SENSOR

    denali = resolve_sensor(DEFAULT_SENSOR)
    return (d.zones == (denali.zones_rows, denali.zones_cols) and d.n_bins == denali.n_bins
            and math.isclose(d.bin_factor * sensor.bin_width_ps, denali.bin_width_ps, rel_tol=1e-6)
            and d.jitter_fwhm_ps == denali.jitter_fwhm_ps and d.pulse_fwhm_ps == denali.pulse_fwhm_ps
            and d.photon_fraction == 1.0)


def point_row(req: Requirement, predicted: Estimate | None, *, learner: str, train_captures: int | None,
              bound: tuple[float, float, float] | None, real: float | None, real_source: str,
              captures: str = "simulated", compare: bool = True, evaluator: Evaluator = Evaluator.TRAINED) -> dict:
    """One row of ``denali_point``: the run's prediction at DENALI's design beside DENALI's real figure.

    Parameters
    ----------
    req : Requirement
    predicted : Estimate or None
        The learner's mean over its seeds at the design (None: never trained there).
    learner : str
        The task's learner (``mlp``, ``cnn1d``, ...).
    train_captures : int or None
        Training captures a run of the learner had (its ``extra["n_train"]``, the early-stopping share included;
        :mod:`~nlosplan.planner.design.budget`).
    bound : (value, lo, hi) or None
        The task's bound at the design (metres or a fraction; an infinite Cramér–Rao bound is None).
    real : float or None
        DENALI's real figure (:func:`real_figure`).
    real_source : str
    captures : {"simulated", "real"}
        What the learner was trained on.
    compare : bool
        Judge the real figure against the requirement (False where the design is not DENALI's: then
        ``real_verdict``, ``agrees`` and ``real_in_interval`` are None).
    evaluator : Evaluator
        Whose runs ``predicted`` is: the learner at the run's budget (``trained``) or at DENALI's budget on the
        learning curve (``learning_curve``).

    Returns
    -------
    dict
        ``task``, ``metric``, ``requirement``, ``threshold``, ``predicted``, ``interval`` ([lo, hi] or None),
        ``seeds``, ``evaluator`` (``"trained"`` or ``"learning_curve"``), ``learner``, ``captures``,
        ``train_captures``, ``bound``, ``bound_interval``, ``bound_name``, ``real``, ``real_source``, ``verdict``
        (the prediction's; None when not trained), ``real_verdict`` (``met``/``not met`` of the real figure; None
        without one), ``agrees`` (None where either verdict is missing), ``real_in_interval`` and
        ``real_beats_bound`` (the real figure lies beyond this world's bound at the design: the simulated world is
        harder than the real one).
    """
    verdict = None if predicted is None else predicted.verdict
    real_verdict = None if real is None or not compare else (MET if req.met(real) else NOT_MET)
    interval = None if predicted is None else [_num(predicted.lo), _num(predicted.hi)]
    b = None if bound is None or not math.isfinite(bound[0]) else bound
    return {"task": req.task, "metric": req.metric, "requirement": req.name, "threshold": req.threshold,
            "predicted": None if predicted is None else _num(predicted.value), "interval": interval,
            "seeds": 0 if predicted is None else predicted.seeds, "evaluator": str(evaluator),
            "learner": learner, "captures": captures, "train_captures": train_captures,
            "bound": None if b is None else float(b[0]),
            "bound_interval": None if b is None else [_num(b[1]), _num(b[2])],
            "bound_name": BOUND_NAMES[req.smaller_is_better], "real": real, "real_source": real_source,
            "verdict": verdict, "real_verdict": real_verdict,
            "agrees": None if verdict is None or real_verdict is None else verdict == real_verdict,
            "real_in_interval": (None if predicted is None or real_verdict is None
                                 else bool(predicted.lo <= real <= predicted.hi)),
            "real_beats_bound": None if b is None or real_verdict is None else _beats(req, real, b)}


def _beats(req: Requirement, real: float, bound: tuple[float, float, float]) -> bool:
    """Whether a real figure lies beyond the bound's interval (below a Cramér–Rao bound, above an observer's)."""
    value, lo, hi = bound
    if req.smaller_is_better:
        return bool(real < (lo if math.isfinite(lo) else value))
    return bool(real > (hi if math.isfinite(hi) else value))


def answer_note(req: Requirement, verdict: str, cost: float | None, denali_cost: float,
                real: float | None, finer: list[str] | tuple = ()) -> str:
    """The sentence beside a requirement's answer when it asks for more than DENALI's hardware (or finds none)
    although DENALI's real figure meets the requirement; empty otherwise.

    Parameters
    ----------
    verdict : str
        The answer's verdict (``met``, ``undecided``, ``not met``).
    cost : float or None
        The answer's design cost (None: no design).
    denali_cost : float
        DENALI's design's cost in the same model.
    real : float or None
        DENALI's real figure.
    finer : sequence of str
        The specs where the answer asks for more than DENALI's (cost terms larger than DENALI's).
    """
    if real is None or not req.met(real):
        return ""
    said = f"DENALI's own hardware meets it in reality ({_fmt(req, real)}, Table 1)"
    if verdict == NOT_MET or cost is None:
        return f"{said}, yet this run finds no design that meets it."
    if cost > denali_cost + 1e-9:
        more = f": more {', '.join(finer)}" if finer else ""
        return (f"This answer asks for more than DENALI's hardware (cost {cost:.2f} against DENALI's "
                f"{denali_cost:.2f}{more}), though {said}.")
    return ""


def denali_point(evidence: Evidence, cheapest: list[dict]) -> list[dict]:
    """The ``denali_point`` rows of a run, one per requirement, at the reference design (see the module notes).

    Parameters
    ----------
    evidence : Evidence
    cheapest : list of dict
        The summary's ``cheapest`` entries, in requirement order (``verdict``, ``cost``, ``design``): each row's
        ``answer_note`` compares the answer with DENALI's hardware.

    Returns
    -------
    list of dict
        :func:`point_row`'s fields, plus ``denali_cost`` (the reference design's cost), ``denali_design``
        (whether the reference is DENALI's geometry: where it is not, ``real_verdict`` and ``agrees`` are None),
        ``answer_note`` and ``train_note`` (why a run had fewer training captures than asked; empty otherwise),
        ``learning_curve`` (:func:`~nlosplan.planner.design.learning_curve.curve_rows`), ``run_budget`` (the
        learner at the run's own budget, the one every other design is judged with: ``train_captures``,
        ``value``, ``interval``, ``verdict``; None if not trained) and ``conservative`` / ``curve_gain``
        (:func:`~nlosplan.planner.design.learning_curve.curve_summary`). Where the curve reached DENALI's 25,200
        captures, ``predicted`` is the learner there (``evaluator`` ``learning_curve``): Table 1's budget.
    """
    base, space = evidence.base, evidence.space
    denali = is_denali_design(base, space.sensor)
    base_terms = evidence.cost_model.terms(base, space)
    rows = []
    for req, answer in zip(evidence.requirements, cheapest):
        runs = evidence.runs(req, base)
        notes = sorted({str(n) for n in (r.extra.get(TRAIN_NOTE) for r in runs if r.finite) if n})
        b = evidence.bound(req, base)
        real, source = real_figure(req)
        if not denali:
            source = f"{source}; not compared: the reference design is not DENALI's 3x3, 128 bins of 92.8 ps"
        own, n_run = seed_interval(req, runs, evidence.spread(req)), run_budget(evidence, req)
        said = curve_summary(req, curve_estimates(evidence, req))
        at = said.at_target
        row = point_row(req, own if at is None else at, learner=evidence.learner(req.task),
                        train_captures=n_run if at is None else DENALI_TRAIN_CAPTURES,
                        bound=None if b is None or not b.finite else (b.value, b.lo, b.hi),
                        real=real, real_source=source, captures="real" if evidence.has_real else "simulated",
                        compare=denali, evaluator=Evaluator.TRAINED if at is None else Evaluator.LEARNING_CURVE)
        row.update(learning_curve=curve_rows(evidence, req), conservative=said.conservative, curve_gain=said.gain,
                   run_budget=None if own is None else {
                       "train_captures": n_run, "value": _num(own.value),
                       "interval": [_num(own.lo), _num(own.hi)], "verdict": own.verdict, "seeds": own.seeds})
        a_verdict, a_cost = answer["verdict"], answer["cost"]
        finer = []
        if answer["key"] is not None:
            d = next((x for x in evidence.designs(req) if x.key() == answer["key"]), None)
            if d is not None:
                terms = evidence.cost_model.terms(d, space)
                finer = [k.replace("_", " ") for k in terms if terms[k] > base_terms[k] + 1e-9]
        note = answer_note(req, a_verdict, a_cost, evidence.cost(base), real, finer) if denali else ""
        rows.append({**row, "denali_design": denali, "denali_cost": evidence.cost(base), "answer_note": note,
                     TRAIN_NOTE: "; ".join(notes)})
    return rows


def bound_conflict(req: Requirement, trained: Estimate, bound: tuple[float, float, float]) -> str:
    """What is inconsistent when a learner's whole 95 % interval lies beyond its task's bound; empty if nothing.

    Parameters
    ----------
    trained : Estimate
        The learner's mean over its seeds at a design.
    bound : (value, lo, hi)
        The bound at the same design (the Cramér–Rao bound has ``lo == hi == value``; the ideal observer's
        interval is its Monte-Carlo Wilson interval; the learner must clear that too).
    """
    value, lo, hi = bound
    if not math.isfinite(value):
        return ""
    if req.smaller_is_better:
        edge = lo if math.isfinite(lo) else value
        if trained.hi < edge:
            return (f"the learner's loc_rmse {_fmt(req, trained.value)} [{_fmt(req, trained.lo)}, "
                    f"{_fmt(req, trained.hi)}] lies wholly below the Cramér–Rao bound {_fmt(req, value)}")
        return ""
    edge = hi if math.isfinite(hi) else value
    if trained.lo > edge:
        return (f"the learner's accuracy {_fmt(req, trained.value)} [{_fmt(req, trained.lo)}, "
                f"{_fmt(req, trained.hi)}] lies wholly above the ideal observer's {_fmt(req, value)} "
                f"[{_fmt(req, lo)}, {_fmt(req, hi)}]")
    return ""


def consistency(evidence: Evidence) -> list[dict]:
    """Every design where a trained learner beats its task's bound beyond its interval (empty: consistent).

    The task's learner at every design it trained in the nominal model and at every budget of its learning curve,
    and every candidate model at the reference design, against the bound of the same design and requirement.

    Returns
    -------
    list of dict
        ``task``, ``requirement``, ``design`` (its key), ``learner``, ``value``, ``lo``, ``hi``, ``seeds``,
        ``bound``, ``bound_lo``, ``bound_hi``, ``bound_name``, ``issue`` (one line).
    """
    out, seen = [], set()
    for req in evidence.requirements:
        if (req.task, req.condition) in seen:
            continue
        seen.add((req.task, req.condition))
        spread, learner = evidence.spread(req), evidence.learner(req.task)
        checks = [(d, learner, seed_interval(req, evidence.runs(req, d), spread)) for d in evidence.designs(req)]
        for m in evidence.config.models:
            if m != learner:
                runs = [evidence.run(Evaluator.TRAINED, req, evidence.base, i, model=m)
                        for i in range(evidence.config.max_seeds)]
                checks.append((evidence.base, m, seed_interval(req, [r for r in runs if r is not None], spread)))
        checks += [(evidence.base, f"{learner} on {n:,} captures", e)
                   for n, e, own in curve_estimates(evidence, req) if not own]
        for d, model, t in checks:
            b = evidence.bound(req, d)
            if t is None or b is None or not b.finite:
                continue
            issue = bound_conflict(req, t, (b.value, b.lo, b.hi))
            if issue:
                out.append({"task": req.task, "requirement": req.name, "design": d.key(), "learner": model,
                            "value": t.value, "lo": t.lo, "hi": t.hi, "seeds": t.seeds, "bound": b.value,
                            "bound_lo": _num(b.lo), "bound_hi": _num(b.hi),
                            "bound_name": BOUND_NAMES[req.smaller_is_better], "issue": issue})
    return out
