"""The package's walls: every import (function-level ones included) points down the layers, and no
module imports itself through others."""

import ast
from pathlib import Path

from drake_grasp.robot.paths import REPO_ROOT

PACKAGE = REPO_ROOT / "drake_grasp"
# Each package and the packages below it that it may import (apps, and the two programs kept at the top
# by name, may import everything).
MAY_IMPORT = {
    "robot": set(),
    "perception": {"robot"},
    "datasets": {"robot"},
    "planning": {"robot", "perception"},
    "simulation": {"robot", "perception", "datasets"},
    "learning": {"robot", "perception", "datasets"},
    "policy": {"robot", "perception", "datasets", "planning", "simulation", "learning"},
    "cell": {"robot", "perception", "datasets", "planning", "simulation", "learning", "policy"},
    "evaluation": {"robot", "perception", "datasets", "planning", "simulation", "learning", "policy", "cell"},
    "service": {"robot", "perception", "datasets", "planning", "simulation", "learning", "policy", "cell"},
}
TOP = {"__init__": {"learning", "cell"}, "__main__": {"apps"}, "simulate": {"apps"},
       "collect_reachability": {"apps"}}


def module_name(path: Path) -> str:
    parts = path.relative_to(REPO_ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports() -> dict[str, set[str]]:
    """Module -> the drake_grasp modules it imports anywhere in its code."""
    modules = {module_name(p): p for p in PACKAGE.rglob("*.py")}
    out = {}
    for name, path in modules.items():
        found = set()
        for node in ast.walk(ast.parse(path.read_text())):
            targets = ([node.module] if isinstance(node, ast.ImportFrom) and node.module and node.level == 0
                       else [a.name for a in node.names] if isinstance(node, ast.Import) else [])
            for target in targets:
                # `from package import module` names a module too.
                if isinstance(node, ast.ImportFrom):
                    found |= {f"{target}.{a.name}" for a in node.names if f"{target}.{a.name}" in modules}
                if target in modules:
                    found.add(target)
        out[name] = {t for t in found if t.startswith("drake_grasp") and t != name}
    return out


def layer(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def test_every_import_points_down_the_layers():
    wrong = []
    for module, targets in imports().items():
        own = layer(module)
        allowed = TOP.get(own) if own in TOP else MAY_IMPORT.get(own)
        for target in targets:
            other = layer(target)
            if other != own and allowed is not None and other not in allowed:
                wrong.append(f"{module} -> {target}")
    assert not wrong, "imports against the walls:\n" + "\n".join(sorted(wrong))
    assert set(MAY_IMPORT) | {"apps"} == {p.name for p in PACKAGE.iterdir() if (p / "__init__.py").exists()}


def test_no_module_imports_itself_through_others():
    graph = imports()
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    cycles = []

    def visit(module: str, path: list[str]) -> None:
        state[module] = 1
        for target in sorted(graph.get(module, ())):
            if state.get(target) == 1:
                cycles.append(" -> ".join([*path[path.index(target):], target]))
            elif target not in state:
                visit(target, [*path, target])
        state[module] = 2

    for module in sorted(graph):
        if module not in state:
            visit(module, [module])
    assert not cycles, "import cycles:\n" + "\n".join(cycles)


def test_the_package_shows_its_pipeline_in_few_entries():
    entries = sorted(p.name for p in PACKAGE.iterdir() if p.name != "__pycache__")
    assert len(entries) <= 15, entries
    assert {"simulate.py", "collect_reachability.py", "__main__.py"} <= set(entries)
