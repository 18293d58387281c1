"""The command line stays thin (docs/architecture.md, room ``cli``): short functions, no private names between commands.

The work of a command lives in the room that owns it (e.g. the Table-2 workflow in
:mod:`nlosplan.calibration.stats_workflow`); a command module parses, checks, calls and prints. Two measurable
consequences are checked on the AST of ``nlosplan/cli``: no function is longer than :data:`MAX_FUNCTION_LINES`, and
no command imports a private name of another command's module (a group's own package, e.g. ``cli/rig/``, excepted).
The checks are tested on planted violations.
"""

from __future__ import annotations

import ast
from pathlib import Path

CLI = Path(__file__).resolve().parents[1] / "nlosplan" / "cli"
#: The longest function (``def`` line to its last line) a command module may hold.
MAX_FUNCTION_LINES = 80


def long_functions(root: Path, limit: int = MAX_FUNCTION_LINES) -> list[str]:
    """``path:line name (n lines)`` of every function longer than ``limit`` lines."""
    out = []
    for path in sorted(root.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > limit:
                    out.append(f"{path.relative_to(root.parent)}:{node.lineno} {node.name} ({n} lines)")
    return out


def _group(module: str) -> str:
    """``nlosplan.cli.rig.run`` -> ``nlosplan.cli.rig`` (a group package); a top-level command is its own group."""
    parts = module.split(".")
    return ".".join(parts[:3]) if len(parts) > 3 else module


def private_imports(root: Path) -> list[str]:
    """``path:line module imports name`` for private names imported from another command's module."""
    out = []
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root.parent.parent).with_suffix("").parts
        module = ".".join(rel[:-1] if rel[-1] == "__init__" else rel)
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("nlosplan.cli"):
                for a in node.names:
                    if a.name.startswith("_") and _group(node.module) != _group(module):
                        out.append(f"{path.relative_to(root.parent)}:{node.lineno} {module} imports "
                                   f"{node.module}.{a.name}")
    return out


def test_no_command_function_is_longer_than_80_lines():
    assert long_functions(CLI) == []


def test_no_command_imports_a_private_name_of_another():
    assert private_imports(CLI) == []


def test_the_checks_catch_planted_violations(tmp_path):
    cli = tmp_path / "nlosplan" / "cli"
    (cli / "rig").mkdir(parents=True)
    body = "\n".join(f"    x = {i}" for i in range(80))
    (cli / "long.py").write_text(f"def run(args):\n{body}\n\n\ndef short():\n    return 1\n")
    (cli / "evaluate.py").write_text("from nlosplan.cli.dataset import _choices, objects\n")
    (cli / "rig" / "run.py").write_text("from nlosplan.cli.rig.capture import _open\n")  # inside its group: fine
    (cli / "rig" / "capture.py").write_text("def _open():\n    pass\n")
    assert long_functions(cli) == ["cli/long.py:1 run (81 lines)"]
    assert private_imports(cli) == ["cli/evaluate.py:1 nlosplan.cli.evaluate imports nlosplan.cli.dataset._choices"]
