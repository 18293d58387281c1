"""The floors of the house (docs/architecture.md): no import cycle, no import up a floor, no private name across rooms,
and the two seams: the simulators' backends are reached only through their API, captures are drawn only by the noise
model.

An AST walk over ``nlosplan/`` (no import is executed): every ``import`` and
``from ... import`` counts, function-local and ``TYPE_CHECKING`` ones
included. Rooms are the subpackages of ``nlosplan``, lowest first as in
:data:`ROOMS`; a few shared modules sit below every room (:data:`SHARED`). A
room may import its own modules, the shared ones and the rooms below it; an
import up a floor is allowed only through a documented plugin hook
(:data:`PLUGIN_HOOKS`, empty today). Outside ``simulators/`` no module imports
a backend's modules (:data:`BACKEND_PACKAGES`) or its simulator classes
(:data:`BACKEND_CLASSES`): they go through :mod:`nlosplan.simulators.api`
(the stability registry excepted, :data:`BACKEND_IMPORTERS`). A Poisson draw
(a call of ``.poisson(``) appears only in the noise model
(:data:`NOISE_MODULE`) and the benchmarks (modules named ``bench``). The
checker is tested on planted violations in a temporary tree, so it can fail.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "nlosplan"

#: Modules below every room: the package face, errors, constants, JAX set-up, the stability catalog's entry type.
SHARED = ("nlosplan", "nlosplan.errors", "nlosplan.constants", "nlosplan._jax", "nlosplan.cases", "nlosplan.files",
          "nlosplan.schema", "nlosplan.progress", "nlosplan.resources")
#: Rooms, lowest first (``stability`` is the catalog registry, a module above the rooms whose cases it lists).
ROOMS = ("sensor_models", "denali", "simulators", "stability", "data", "calibration", "tasks", "hardware", "planner",
         "experiments", "reports", "cli")
#: (importing module, imported module) pairs allowed to go up a floor: documented plugin hooks. None today.
PLUGIN_HOOKS: frozenset[tuple[str, str]] = frozenset()
#: The backends' packages: only ``simulators/`` imports them (the rest goes through ``nlosplan.simulators``).
BACKEND_PACKAGES = ("nlosplan.simulators.fast", "nlosplan.simulators.mitsuba")
#: Backend classes the simulators' face exports for users and tests, not for the rooms above.
BACKEND_CLASSES = ("FastSimulator", "FastBackend", "TwinSimulator", "TwinBackend")
#: Modules outside ``simulators/`` allowed to import a backend's module: the stability registry lists every room's cases.
BACKEND_IMPORTERS = frozenset({"nlosplan.stability"})
#: The one module that draws captures (Poisson noise and the clip).
NOISE_MODULE = "nlosplan.sensor_models.noise"


def modules(root: Path) -> dict[str, Path]:
    """Dotted module name -> file, for every ``.py`` under ``root`` (a package folder named ``nlosplan``)."""
    out = {}
    for path in sorted(root.rglob("*.py")):
        parts = list(path.relative_to(root.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def imports(mods: dict[str, Path]) -> list[tuple[str, str, str | None, int]]:
    """``(importer, imported module, imported name or None, line)`` for every nlosplan import anywhere in a module.

    ``from a.b import c`` imports the module ``a.b.c`` when there is one, else the name ``c`` of ``a.b``.
    Attribute reads of a private name through a module alias (``import a.b as m; m._x``) count as imports of it.
    """
    found = []
    for name, path in mods.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        aliases: dict[str, str] = {}
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                for a in node.names:
                    if a.name.split(".")[0] == "nlosplan":
                        found.append((name, a.name, None, node.lineno))
                        if a.asname:
                            aliases[a.asname] = a.name
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                    target = ".".join(base + ([node.module] if node.module else []))
                else:
                    target = node.module or ""
                if target.split(".")[0] != "nlosplan":
                    continue
                for a in node.names:
                    sub = f"{target}.{a.name}"
                    if sub in mods:
                        found.append((name, sub, None, node.lineno))
                        aliases[a.asname or a.name] = sub
                    else:
                        found.append((name, target, a.name, node.lineno))
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in aliases
                    and node.attr.startswith("_") and not node.attr.startswith("__")):
                found.append((name, aliases[node.value.id], node.attr, node.lineno))
    return found


def room(module: str) -> str | None:
    """The room of a module (None for the shared modules below every room)."""
    if module in SHARED:
        return None
    parts = module.split(".")
    return "cli" if parts[1] == "__main__" else parts[1]


def rank(module: str) -> int:
    r = room(module)
    return -1 if r is None else ROOMS.index(r)


def cycles(mods: dict[str, Path], edges) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan), each sorted."""
    graph = {m: sorted({t for s, t, _, _ in edges if s == m and t in mods and t != m}) for m in mods}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:  # recursion depth = the longest import chain (tens of modules)
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in graph:
        if v not in index:
            visit(v)
    return out


def poisson_calls(mods: dict[str, Path]) -> list[tuple[str, int]]:
    """``(module, line)`` of every call of an attribute named ``poisson`` (``rng.poisson(...)``, ``jax.random.poisson``)."""
    found = []
    for name, path in mods.items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "poisson":
                found.append((name, node.lineno))
    return found


def seam_violations(root: Path, mods: dict[str, Path], edges) -> dict[str, list[str]]:
    """The two seams: ``backend`` (a backend reached past the simulators' API) and ``poisson`` (a draw outside the noise model)."""
    out: dict[str, list[str]] = {"backend": [], "poisson": []}
    for src, target, attr, line in edges:
        if room(src) == "simulators" or src in BACKEND_IMPORTERS:
            continue
        where = f"{mods[src].relative_to(root.parent)}:{line}"
        if any(target == p or target.startswith(p + ".") for p in BACKEND_PACKAGES):
            out["backend"].append(f"{where}: {src} imports the backend module {target}")
        elif attr in BACKEND_CLASSES and room(target) == "simulators":
            out["backend"].append(f"{where}: {src} imports the backend class {target}.{attr}")
    for src, line in poisson_calls(mods):
        if src != NOISE_MODULE and src.rpartition(".")[2] != "bench":
            out["poisson"].append(f"{mods[src].relative_to(root.parent)}:{line}: {src} draws Poisson counts "
                                  f"(use {NOISE_MODULE}.CaptureNoise)")
    return out


def violations(root: Path) -> dict[str, list[str]]:
    """Everything that breaks a floor or a seam, by rule: ``unknown room``, ``cycle``, ``upward``, ``private``,
    ``backend``, ``poisson``."""
    mods = modules(root)
    edges = imports(mods)
    out: dict[str, list[str]] = {"unknown room": [], "cycle": [], "upward": [], "private": []}
    for m in mods:
        if room(m) is not None and room(m) not in ROOMS:
            out["unknown room"].append(f"{m} (room {room(m)!r} is not in ROOMS)")
    out["cycle"] = [" <-> ".join(c) for c in cycles(mods, edges)]
    for src, target, attr, line in edges:
        if target not in mods:
            continue  # a name of the package face that no module defines: Python would fail first
        where = f"{mods[src].relative_to(root.parent)}:{line}"
        if rank(target) > rank(src) and (src, target) not in PLUGIN_HOOKS and room(src) in ROOMS:
            out["upward"].append(f"{where}: {src} ({room(src)}) imports {target} ({room(target)})")
        if room(src) == room(target):
            continue
        private_module = any(p.startswith("_") and not p.startswith("__") for p in target.split(".")[1:])
        if (attr and attr.startswith("_") and not attr.startswith("__")) or (private_module and target not in SHARED):
            out["private"].append(f"{where}: {src} ({room(src)}) uses private {target}{'.' + attr if attr else ''}")
    out.update(seam_violations(root, mods, edges))
    return out


CLEAN = {"unknown room": [], "cycle": [], "upward": [], "private": [], "backend": [], "poisson": []}


def test_nlosplan_keeps_its_floors():
    found = violations(PACKAGE)
    assert found == CLEAN, found


def test_every_room_is_a_subpackage_with_a_face():
    for r in ROOMS:
        if r == "stability":
            assert (PACKAGE / "stability.py").is_file()
            continue
        assert (PACKAGE / r / "__init__.py").is_file(), r


def _write(root: Path, files: dict[str, str]) -> Path:
    pkg = root / "nlosplan"
    for rel, text in {"__init__.py": "", "errors.py": "", **files}.items():
        path = pkg / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        for parent in path.relative_to(pkg).parents:
            init = pkg / parent / "__init__.py"
            if not init.exists():
                init.write_text("")
        path.write_text(text)
    return pkg


def test_the_checker_passes_a_clean_tree(tmp_path):
    pkg = _write(tmp_path, {
        "sensor_models/config.py": "from nlosplan.errors import UserError\n",
        "simulators/api.py": "from nlosplan.sensor_models.config import UserError\nfrom . import scene\n",
        "simulators/scene.py": "import nlosplan.errors\n",
        "cli/main.py": "def f():\n    from nlosplan.simulators.api import UserError\n",
    })
    assert violations(pkg) == CLEAN


def test_the_checker_catches_planted_violations(tmp_path):
    pkg = _write(tmp_path, {
        # a cycle closed by a function-local import
        "tasks/a.py": "from nlosplan.tasks import b\n",
        "tasks/b.py": "def f():\n    from nlosplan.tasks.a import thing\n",
        # an import up a floor (sensor_models -> cli), also function-local
        "sensor_models/low.py": "def g():\n    import nlosplan.cli.top\n",
        "cli/top.py": "",
        # private names across rooms: by name, through a module alias, and a private module
        "simulators/fast.py": "def _to_jax(x):\n    return x\n",
        "simulators/_hidden.py": "",
        "tasks/bounds.py": ("from nlosplan.simulators.fast import _to_jax\n"
                            "import nlosplan.simulators.fast as f\nf._to_jax(1)\n"
                            "from nlosplan.simulators import _hidden\n"),
        # a module outside every room
        "attic/old.py": "",
    })
    found = violations(pkg)
    assert found["cycle"] == ["nlosplan.tasks.a <-> nlosplan.tasks.b"]
    assert len(found["upward"]) == 1 and "nlosplan.sensor_models.low (sensor_models) imports nlosplan.cli.top" in found["upward"][0]
    assert len(found["private"]) == 3
    assert any("nlosplan.simulators.fast._to_jax" in v for v in found["private"])
    assert any("nlosplan.simulators._hidden" in v for v in found["private"])
    assert found["unknown room"] == ["nlosplan.attic (room 'attic' is not in ROOMS)",
                                     "nlosplan.attic.old (room 'attic' is not in ROOMS)"]


def test_the_checker_catches_a_backend_reached_past_the_api(tmp_path):
    pkg = _write(tmp_path, {
        "simulators/api.py": "from nlosplan.simulators.fast.simulator import FastSimulator\n",  # inside: fine
        "simulators/fast/simulator.py": "class FastSimulator:\n    pass\n",
        "simulators/mitsuba/render.py": "",
        "stability.py": "from nlosplan.simulators.fast import simulator\n",  # the registry: allowed
        "tasks/bounds.py": "from nlosplan.simulators.fast.simulator import FastSimulator\n",
        "planner/data.py": "def f():\n    from nlosplan.simulators import FastSimulator, expected_batch\n",
        "cli/bench.py": "import nlosplan.simulators.mitsuba.render\n",
        "data/build.py": "from nlosplan.simulators import api\n",  # the seam: fine
    })
    found = violations(pkg)
    assert len(found["backend"]) == 3, found["backend"]
    assert any("nlosplan.tasks.bounds imports the backend module nlosplan.simulators.fast.simulator" in v
               for v in found["backend"])
    assert any("nlosplan.planner.data imports the backend class nlosplan.simulators.FastSimulator" in v
               for v in found["backend"])
    assert any("nlosplan.cli.bench imports the backend module nlosplan.simulators.mitsuba.render" in v
               for v in found["backend"])
    assert {k: v for k, v in found.items() if k != "backend"} == {k: v for k, v in CLEAN.items() if k != "backend"}


def test_the_checker_catches_a_poisson_draw_outside_the_noise_model(tmp_path):
    pkg = _write(tmp_path, {
        "sensor_models/noise.py": "def draw(rng, m):\n    return rng.poisson(m)\n",  # the noise model: fine
        "sensor_models/bench.py": "def f(rng):\n    return rng.poisson(3.0)\n",  # a benchmark: fine
        "planner/simrig.py": "def observe(rng, lam):\n    return rng.poisson(lam).mean(0)\n",
        "hardware/emu.py": "import jax\n\ndef f(k, m):\n    return jax.random.poisson(k, m)\n",
    })
    found = violations(pkg)
    assert sorted(v.split(":")[0] for v in found["poisson"]) == ["nlosplan/hardware/emu.py", "nlosplan/planner/simrig.py"]
    assert "nlosplan.planner.simrig draws Poisson counts" in " ".join(found["poisson"])


def test_a_plugin_hook_must_be_listed(tmp_path, monkeypatch):
    pkg = _write(tmp_path, {"simulators/backend.py": "def load():\n    import nlosplan.hardware.plugin\n",
                            "hardware/plugin.py": ""})
    assert len(violations(pkg)["upward"]) == 1
    monkeypatch.setattr(__import__(__name__), "PLUGIN_HOOKS",
                        frozenset({("nlosplan.simulators.backend", "nlosplan.hardware.plugin")}))
    assert violations(pkg)["upward"] == []


@pytest.mark.parametrize("module, expected", [("nlosplan.errors", None), ("nlosplan.cli.rig.run", "cli"),
                                              ("nlosplan.__main__", "cli"), ("nlosplan.denali.rig", "denali")])
def test_rooms_of_modules(module, expected):
    assert room(module) == expected
