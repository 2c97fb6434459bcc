"""The orchestrator's layout: three concerns in three folders, imports one way only."""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PKG = ROOT / "orchestrator"
# A layer may import from itself and from the layers before it, never from a later one.
LAYERS = ("engine", "experiments", "studies")


def _module_imports():
    """{module: set of orchestrator modules it imports}, module- and function-level alike."""
    graph = {}
    for path in PKG.rglob("*.py"):
        rel = path.relative_to(ROOT).with_suffix("")
        name = ".".join(rel.parts)
        pkg_parts = rel.parts[:-1]
        deps = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    base = list(pkg_parts[:len(pkg_parts) - node.level + 1])
                    target = ".".join(base + ([node.module] if node.module else []))
                else:
                    target = node.module or ""
                names = [f"{target}.{a.name}" for a in node.names]
                for t in [target, *names]:
                    if t.startswith("orchestrator") and (ROOT / (t.replace(".", "/") + ".py")).exists():
                        deps.add(t)
            elif isinstance(node, ast.Import):
                deps.update(a.name for a in node.names if a.name.startswith("orchestrator"))
        graph[name] = deps - {name}
    return graph


def test_the_orchestrator_has_one_folder_per_concern():
    for layer in LAYERS:
        assert (PKG / layer / "__init__.py").is_file()
    loose = sorted(p.name for p in PKG.glob("*.py"))
    assert loose == ["__init__.py", "__main__.py", "cli.py"]


def test_no_layer_imports_a_later_layer():
    for module, deps in _module_imports().items():
        parts = module.split(".")
        if len(parts) < 3:
            continue  # the CLI on top may import everything
        mine = LAYERS.index(parts[1])
        for dep in deps:
            dparts = dep.split(".")
            if len(dparts) >= 3:
                assert LAYERS.index(dparts[1]) <= mine, f"{module} imports {dep} from a later layer"


def test_the_import_graph_has_no_cycle():
    graph = _module_imports()
    state = {}

    def visit(node, path):
        state[node] = "open"
        for dep in graph.get(node, ()):
            if state.get(dep) == "open":
                raise AssertionError("import cycle: " + " -> ".join(path + [node, dep]))
            if dep not in state:
                visit(dep, path + [node])
        state[node] = "done"

    for node in graph:
        if node not in state:
            visit(node, [])
