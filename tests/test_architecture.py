"""The layers import only downwards, and no module imports another in a cycle.

The import graph is read from the sources (every ``import`` statement, at module level or in a
function, except those under ``if TYPE_CHECKING:``), so a lazy import counts as much as an
eager one: a cycle through a function-level import is still a cycle.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("execution", "follow_env", "policies", "train", "eval", "bench", "bridge")
# follow_env's layers, lowest first: a module may import its own layer and the ones below.
# experiments (reproductions of the sources' hardware experiments) may use every layer.
LAYERS = ("sim", "world", "platforms", "sensors", "tasks", "experiments")


def _modules() -> dict[str, Path]:
    out = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            if "__pycache__" in path.parts:
                continue
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = path
    return out


MODULES = _modules()


def _type_checking_lines(tree: ast.Module) -> set[int]:
    lines: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            for child in node.body:
                lines.update(range(child.lineno, (child.end_lineno or child.lineno) + 1))
    return lines


def _imports(name: str, path: Path) -> Iterator[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    skip = _type_checking_lines(tree)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    for node in ast.walk(tree):
        if getattr(node, "lineno", None) in skip:
            continue
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[: len(parts) - node.level + 1] + ([base] if base else []))
            for alias in node.names:
                full = f"{base}.{alias.name}"
                yield full if full in MODULES else base


def _project(target: str) -> str | None:
    """The project module an import names (the longest known prefix), or None."""
    while target:
        if target in MODULES:
            return target
        target = target.rpartition(".")[0]
    return None


GRAPH = {
    name: {t for raw in _imports(name, path) if (t := _project(raw)) and t != name}
    for name, path in MODULES.items()
}


def _layer(module: str) -> int | None:
    parts = module.split(".")
    if parts[0] != "follow_env" or len(parts) < 2 or parts[1] not in LAYERS:
        return None
    return LAYERS.index(parts[1])


def test_the_graph_covers_the_project() -> None:
    assert len(MODULES) > 60
    assert "follow_env.sim.runner" in GRAPH["follow_env.tasks.person_follow.env"] or any(
        "follow_env.sim" in t for t in GRAPH["follow_env.tasks.person_follow.env"]
    )


def test_no_module_imports_another_in_a_cycle() -> None:
    # Tarjan's strongly connected components.
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(GRAPH[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for v in sorted(GRAPH):
        if v not in index:
            visit(v)
    assert cycles == []


@pytest.mark.parametrize("module", sorted(m for m in MODULES if _layer(m) is not None))
def test_follow_env_layers_import_only_downwards(module: str) -> None:
    mine = _layer(module)
    for target in GRAPH[module]:
        theirs = _layer(target)
        if target.startswith("follow_env."):
            assert theirs is not None, f"{module} imports {target}"
            assert theirs <= mine, f"{module} imports {target}"


def test_follow_env_imports_no_policy_training_evaluation_or_bridge() -> None:
    for module, targets in GRAPH.items():
        if module.startswith("follow_env"):
            bad = {t for t in targets if t.split(".")[0] in ("policies", "train", "eval", "bridge")}
            assert not bad, f"{module} imports {bad}"


def test_the_execution_layer_imports_nothing_of_the_project() -> None:
    # Evaluation, tuning and training all place their work through it: it knows none of them.
    ours = set(PACKAGES) - {"execution"}
    for module, targets in GRAPH.items():
        if module.startswith("execution"):
            bad = {t for t in targets if t.split(".")[0] in ours}
            assert not bad, f"{module} imports {bad}"


def test_policies_see_tasks_only_through_their_specs() -> None:
    allowed = {
        "follow_env.sim.checks",
        "follow_env.tasks.person_follow.spec",
        "follow_env.tasks.line_trace.spec",
        "follow_env.tasks.spec",
    }
    for module, targets in GRAPH.items():
        if module.split(".")[0] == "policies":
            env = {t for t in targets if t.startswith("follow_env")}
            assert env <= allowed, f"{module} imports {env - allowed}"
            assert not {t for t in targets if t.split(".")[0] in ("train", "eval", "bridge")}


def test_the_leaves_keep_to_themselves() -> None:
    # eval and the bridge never import training; the bridge imports no evaluation either;
    # training may use the evaluation library (its model card's comparison).
    for module, targets in GRAPH.items():
        top = module.split(".")[0]
        tops = {t.split(".")[0] for t in targets}
        if top == "eval":
            assert not tops & {"train", "bridge"}, module
        if top == "bridge":
            assert not tops & {"train", "eval"}, module
        if top == "train":
            assert "bridge" not in tops, module


# What runs on a robot's PC: the link, the protocol, the runner, the perception sources and the
# command line. They may read the platform's and the task's definitions, never build a
# simulation (the emulator, its world and the monitor's --sim driver do, on purpose).
ROBOT_SIDE = (
    "bridge.fit",
    "bridge.link",
    "bridge.runner",
    "bridge.perception",
    "bridge.sources",
    "bridge.cli",
)


def test_the_robot_side_of_the_bridge_builds_no_simulation() -> None:
    import subprocess
    import sys

    code = (
        "import sys; import " + ", ".join(ROBOT_SIDE) + "; "
        "bad = [m for m in sys.modules if m.startswith(('follow_env.sim.runner', "
        "'follow_env.sim.compose', 'follow_env.tasks.person_follow.kernel', 'torch', "
        "'stable_baselines3', 'eval', 'train'))]; print(bad)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == "[]"


def test_no_module_is_over_about_500_lines() -> None:
    long = {m: n for m, p in MODULES.items() if (n := len(p.read_text().splitlines())) > 560}
    assert long == {}
