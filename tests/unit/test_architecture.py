"""The layers import one way only, and no module imports in a circle.

Layers, lowest first (a module may import its own layer and the layers below it):

0. core: types, configs, scenario dataclasses (`agent.core`)
1. planning: threats, via-points, encounters, reference paths, MPC, ORCA, controller
   (`agent.planning`)
2. simulation: dynamics, link faults, fault plans, schedule, the lockstep loop (`world.sim`)
3. wire: key expressions, messages, codec, transport settings (the `eifp_wire` package), the
   scenario file format (`world.scenario_file`), run directories and files made safely
   (`agent.files`)
4. runtime: the robot and world processes and their plumbing (`agent.node`, `agent.fleet`,
   `agent.process`, `agent.flags`, `world.node`, `world.router`, `world.recorder`,
   `world.mcap_log`), and the IR-SIM behaviour (`agent.irsim`)
5. experiments and analysis (`orchestrator.experiments`, `orchestrator.analysis`)
6. CLI (`orchestrator.cli`)
7. scripts: stand-alone tools in ``scripts/`` (not installed; nothing imports them)

`eifp_wire` is the one wire layer: no other module serialises messages (imports msgpack)
or builds a key expression of a run.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("eifp_wire", "agent", "world", "orchestrator")
TOOLS = "scripts"
"""A folder of stand-alone scripts: modules ``scripts.<name>``, in the top layer."""
LAYERS: tuple[tuple[str, ...], ...] = (
    ("agent.core",),
    ("agent.planning",),
    ("world.sim",),
    ("eifp_wire", "world.scenario_file", "agent.files"),
    ("agent.node", "agent.fleet", "agent.process", "agent.flags", "agent.security",
     "agent.__main__", "agent.irsim",
     "world.node", "world.router", "world.recorder", "world.mcap_log", "world.__main__"),
    ("orchestrator.experiments", "orchestrator.analysis"),
    ("orchestrator.cli", "orchestrator.__main__"),
    (TOOLS,),
)
LAYER_NAMES = ("core", "planning", "simulation", "wire", "runtime", "experiments", "cli",
               "scripts")
WIRE = "eifp_wire"
PURE_FORBIDDEN = ("zenoh", "yaml", "matplotlib", "psutil", "subprocess", "socket", "irsim")
"""Layers 0-2 do no I/O and know no simulator (IR-SIM is adapted at an edge, `agent.irsim`);
the wire layer may read YAML but never touches zenoh."""


def module_name(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
    return ".".join(parts)


def project_modules() -> dict[str, Path]:
    mods = {}
    for pkg in (*PACKAGES, TOOLS):
        for path in (ROOT / pkg).rglob("*.py"):
            mods[module_name(path)] = path
    return mods


MODULES = project_modules()


def layer_of(module: str) -> int | None:
    for i, prefixes in enumerate(LAYERS):
        if any(module == p or module.startswith(p + ".") for p in prefixes):
            return i
    return None


def imports_of(path: Path, module: str) -> set[str]:
    """Every module `path` imports, anywhere in the file (function-local imports too)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*up, base] if base else up)
            for alias in node.names:
                full = f"{base}.{alias.name}"
                found.add(full if full in MODULES else base)
    return found


def project_imports(module: str) -> set[str]:
    """The project modules `module` imports (a package import counts as its __init__)."""
    out = set()
    for name in imports_of(MODULES[module], module):
        while name and name not in MODULES:
            name = name.rpartition(".")[0]
        if name and name != module:
            out.add(name)
    return out


GRAPH = {m: project_imports(m) for m in MODULES}


def test_every_module_has_a_layer() -> None:
    package_inits = {"agent", "world", "orchestrator"}
    missing = sorted(m for m in MODULES if layer_of(m) is None and m not in package_inits)
    assert not missing, f"modules outside every layer: {missing}"


@pytest.mark.parametrize("module", sorted(MODULES))
def test_no_upward_import(module: str) -> None:
    mine = layer_of(module)
    if mine is None:
        return
    upward = sorted(
        f"{dep} ({LAYER_NAMES[layer_of(dep)]})" for dep in GRAPH[module]
        if layer_of(dep) is not None and layer_of(dep) > mine)
    assert not upward, f"{module} ({LAYER_NAMES[mine]}) imports upward: {upward}"


@pytest.mark.parametrize("module", sorted(m for m in MODULES if (layer_of(m) or 0) <= 3))
def test_lower_layers_do_no_io(module: str) -> None:
    mine = layer_of(module)
    forbidden = ("zenoh",) if mine == 3 else PURE_FORBIDDEN
    external = {name.split(".")[0] for name in imports_of(MODULES[module], module)}
    bad = sorted(external & set(forbidden))
    assert not bad, f"{module} ({LAYER_NAMES[mine or 0]}) imports {bad}"


def test_no_import_cycles() -> None:
    # Tarjan's strongly connected components over the module graph.
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in GRAPH[v]:
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
                cycles.append(sorted(comp))

    for v in sorted(GRAPH):
        if v not in index:
            visit(v)
    assert not cycles, f"import cycles: {cycles}"


def test_the_checker_sees_an_upward_import(tmp_path: Path) -> None:
    """The walk finds function-local imports, so an upward one could not hide in a function."""
    src = tmp_path / "probe.py"
    src.write_text("def f():\n    from orchestrator.cli import main\n    return main\n")
    assert "orchestrator.cli.main" in imports_of(src, "agent.core.probe") or \
        "orchestrator.cli" in imports_of(src, "agent.core.probe")


def is_wire(module: str) -> bool:
    return module == WIRE or module.startswith(WIRE + ".")


KEY_LITERAL = re.compile(r"(?<![\w-])eifp/|^/(poses|cmd|config|control|debug|alive)(/|$)")
"""A string that spells a run's key expression: one under the key root (``eifp/r1/cmd/3``),
or an f-string piece that appends a key's segment to a prefix (``f"{prefix}/cmd/{i}"``)."""


def key_literals(path: Path) -> list[str]:
    """Every string in `path`, docstrings aside, that builds a key expression (`KEY_LITERAL`),
    and every import of the key root (``KEY_ROOT``), as ``line: text``."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    docstrings = {id(node.value) for node in ast.walk(tree)
                  if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)}
    found = []
    for node in ast.walk(tree):
        if (isinstance(node, ast.Constant) and isinstance(node.value, str)
                and id(node) not in docstrings and KEY_LITERAL.search(node.value)):
            found.append(f"{node.lineno}: {node.value!r}")
        elif isinstance(node, ast.ImportFrom) and any(a.name == "KEY_ROOT" for a in node.names):
            found.append(f"{node.lineno}: imports KEY_ROOT")
    return found


@pytest.mark.parametrize("module", sorted(m for m in MODULES if not is_wire(m)))
def test_only_the_wire_layer_serialises_messages(module: str) -> None:
    external = {name.split(".")[0] for name in imports_of(MODULES[module], module)}
    assert "msgpack" not in external, f"{module} imports msgpack: encode with {WIRE}'s messages"


@pytest.mark.parametrize("module", sorted(m for m in MODULES if not is_wire(m)))
def test_only_the_wire_layer_builds_key_expressions(module: str) -> None:
    found = key_literals(MODULES[module])
    assert not found, f"{module} builds key expressions (use {WIRE}.RunKeys): {found}"


def test_the_checker_sees_a_key_built_outside_the_wire_layer(tmp_path: Path) -> None:
    """Literal keys and keys built in f-strings are found; prose in a docstring is not."""
    src = tmp_path / "probe.py"
    src.write_text('"""Publishes on ``eifp/<run>/cmd/<id>``."""\n'
                   "from eifp_wire.keys import KEY_ROOT\n"
                   "A = 'eifp/r1/poses/0'\n"
                   "def f(p, i):\n    return f'{p}/cmd/{i}'\n"
                   "B = 'docs/config/x.yaml'\n")
    assert [hit.split(":")[0] for hit in key_literals(src)] == ["2", "3", "5"]


def test_scripts_are_checked_too() -> None:
    """Scripts are in the top layer: they may import anything, nothing imports them."""
    scripts = [m for m in MODULES if m.startswith(TOOLS + ".")]
    assert scripts and all(layer_of(m) == len(LAYERS) - 1 for m in scripts)
