"""``nlosplan check``: the stability catalog."""

from __future__ import annotations

import sys

from nlosplan.cli.common import emit, progress_bar, sub_parser

def _cmd_check(args) -> int:
    from nlosplan.reports.tables import format_table
    from nlosplan.stability import all_cases, run_apart

    cases = all_cases()
    try:
        with progress_bar(args, len(cases), "stability cases", "case") as bar:
            results = run_apart(cases, None if bar is None else lambda _r: bar.update(1))
    except RuntimeError as exc:  # the cases' process died (memory, a signal): one line, a failed check
        print(f"nlosplan check: {exc}", file=sys.stderr)
        return 1
    ok = all(r.passed for r in results)
    data = {"passed": ok, "cases": [{"name": r.name, "passed": r.passed, "requirement": r.requirement,
                                     "detail": r.detail, "seconds": round(r.seconds, 3)} for r in results]}
    rows = [{"case": r.name, "must hold": r.requirement, "measured": r.detail,
             "result": "pass" if r.passed else "FAIL"} for r in results]
    n_pass = sum(r.passed for r in results)
    text = format_table(rows) + f"\n\n{n_pass} of {len(results)} cases passed"
    emit(args, data, text)
    return 0 if ok else 1


def add(sub) -> None:
    """The ``check`` subcommand."""
    chk = sub_parser(sub, "check", "check", "run the stability catalog (stiff and extreme cases); exit 0 only if all pass")
    chk.add_argument("--json", action="store_true", help='print {"cases": [{"name", "passed", "detail"}...]}')
    chk.set_defaults(func=_cmd_check)
