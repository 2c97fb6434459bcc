"""The layout: the package's layers import one way only (read with ``ast``), the orchestrator has
one folder per concern, and the tests are laid out like the package."""

import ast
import functools
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
TESTS = ROOT / "tests"
PKG = ROOT / "orchestrator"
PACKAGES = ("ctoolchain", "tapmp", "fmu_common", "fmu_plant", "fmu_controller", "orchestrator")
# A layer may import from itself and from the layers before it, never from a later one: the engine
# (the SSP reader, the master, any FMUs), the builder (TAPMP's FMUs and SSP), the tool (scenarios,
# runs, results, reports, for any controller), the paper study (its tables, reproduction,
# calibration), the studies on Dask (which know no paper either: FORBIDDEN).
LAYERS = ("engine", "builder", "tool", "paper", "studies")

# {package: what it must not import}: the C toolchain knows nothing of the project; the model knows
# no FMU and no master; the FMI runtime knows only the model; the FMU adapters know the model and the
# runtime; the orchestrator's engine knows no TAPMP (model, FMUs, builder), scenario, paper, study or
# command line; the builder no tool, paper, study or command line; the tool knows no paper, study or
# command line; the paper study knows no study or command line; studies no paper and no command
# line (a tuning's published rows are handed in by the command). Standard library and third-party
# imports are free.
FORBIDDEN = {
    "ctoolchain": ("tapmp", "fmu_common", "fmu_plant", "fmu_controller", "orchestrator"),
    "tapmp": ("fmu_common", "fmu_plant", "fmu_controller", "orchestrator"),
    "fmu_common": ("fmu_plant", "fmu_controller", "orchestrator"),
    "fmu_plant": ("fmu_controller", "orchestrator"),
    "fmu_controller": ("fmu_plant", "orchestrator"),
    "orchestrator.engine": ("tapmp", "fmu_common", "fmu_plant", "fmu_controller", "orchestrator.builder", "orchestrator.tool", "orchestrator.paper", "orchestrator.studies", "orchestrator.cli"),
    "orchestrator.builder": ("orchestrator.tool", "orchestrator.paper", "orchestrator.studies", "orchestrator.cli"),
    "orchestrator.tool": ("orchestrator.paper", "orchestrator.studies", "orchestrator.cli"),
    "orchestrator.paper": ("orchestrator.studies", "orchestrator.cli"),
    "orchestrator.studies": ("orchestrator.paper", "orchestrator.cli"),
}

# Test folders, named like the package's parts (tool and paper as orchestrator's); "cli" holds the
# end-to-end runs of the tapmp command, "project" the checks of the repository as a whole (docs,
# README commands, clean checkout, wheel, tests/run.sh, benchmarks), "support" the helpers the
# tests share (imported as tests.support.<module>), no test.
TEST_FOLDERS = ("model", "fmu", "engine", "tool", "paper", "studies", "cli", "interop", "project")
HELPERS = "support"
# What may sit at tests/'s root: the package marker, the shared fixtures, this file.
TEST_ROOT_FILES = {"__init__.py", "conftest.py", "test_layout.py"}


def _in(module: str, package: str) -> bool:
    return module == package or module.startswith(package + ".")


@functools.cache  # one parse of the package for every rule
def _imports() -> dict:
    """{module: {imported project module or name: line}} for every module of PACKAGES,
    module- and function-level alike, relative imports resolved."""
    graph = {}
    for top in PACKAGES:
        for path in sorted((ROOT / top).rglob("*.py")):
            rel = path.relative_to(ROOT).with_suffix("")
            is_init = rel.name == "__init__"
            parts = rel.parts[:-1] if is_init else rel.parts
            package = list(parts) if is_init else list(parts[:-1])
            deps = {}
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                if isinstance(node, ast.ImportFrom):
                    if node.level:
                        base = package[:len(package) - node.level + 1]
                        target = ".".join(base + ([node.module] if node.module else []))
                    else:
                        target = node.module or ""
                    targets = [target, *(f"{target}.{a.name}" for a in node.names)]
                elif isinstance(node, ast.Import):
                    targets = [a.name for a in node.names]
                else:
                    continue
                for t in targets:
                    if t.split(".")[0] in PACKAGES:
                        deps.setdefault(t, node.lineno)
            graph[".".join(parts)] = deps
    return graph


def _module_imports(package: str = "orchestrator"):
    """{module of ``package`` (every package if ""): set of the project's modules it imports}, module- and
    function-level alike. An import of a package (``from . import cmodel`` names ``tapmp`` too) counts as
    its __init__ only when that package is not the importer's own: Python has run the importer's packages'
    __init__ before the importer, so they are no dependency of it."""
    graph = {}
    for module, deps in _imports().items():
        if package and not _in(module, package):
            continue
        found = set()
        for d in deps:
            path = ROOT / d.replace(".", "/")
            if path.with_suffix(".py").exists():
                found.add(d)
            elif (path / "__init__.py").exists() and not _in(module, d):
                found.add(d)
        graph[module] = found - {module}
    return graph


@pytest.mark.parametrize("package", FORBIDDEN)
def test_each_layer_imports_only_the_layers_below_it(package):
    broken = [f"{module} imports {dep} (line {line})"
              for module, deps in _imports().items() if _in(module, package)
              for dep, line in deps.items() if any(_in(dep, f) for f in FORBIDDEN[package])]
    assert not broken, f"{package} must not import {', '.join(FORBIDDEN[package])}: " + "; ".join(broken)


def test_the_orchestrator_has_one_folder_per_concern():
    for layer in LAYERS:
        assert (PKG / layer / "__init__.py").is_file()
    # exactly the layers: no second home of the tool or the paper study under an older name
    # and cli/, the `tapmp` command on top of them all
    folders = sorted(p.name for p in PKG.iterdir() if p.is_dir() and p.name != "__pycache__")
    assert folders == sorted((*LAYERS, "cli"))
    setuptools = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"]
    # the layers' own data folders (the builder's templates) are packages of the wheel too, below a layer
    assert sorted(p for p in setuptools if p.count(".") == 1 and p.startswith("orchestrator.")) == sorted(
        f"orchestrator.{x}" for x in (*LAYERS, "cli"))
    loose = sorted(p.name for p in PKG.glob("*.py"))
    # errors.py: the user-error type every layer raises, below all of them (it imports only the base of
    # every user error, from the lowest package)
    assert loose == ["__init__.py", "__main__.py", "errors.py"]
    imports = [line for line in (PKG / "errors.py").read_text().splitlines() if "import" in line.split("#")[0]]
    assert imports == ["from ctoolchain.errors import UserError"]


def test_no_layer_imports_a_later_layer():
    for module, deps in _module_imports().items():
        parts = module.split(".")
        if len(parts) < 3 or parts[1] == "cli":
            continue  # the CLI on top may import everything
        mine = LAYERS.index(parts[1])
        for dep in deps:
            dparts = dep.split(".")
            if len(dparts) >= 3:
                assert LAYERS.index(dparts[1]) <= mine, f"{module} imports {dep} from a later layer"


def test_the_import_graph_has_no_cycle():
    # every package, function-level imports included (a cycle hidden in a function body is one too)
    graph = _module_imports("")
    assert all(any(_in(m, package) for m in graph) for package in PACKAGES)  # the walk sees every package
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


def _test_files():
    return sorted(p for p in TESTS.rglob("test_*.py") if ".venv" not in p.parts)


def test_every_test_file_is_in_the_folder_of_what_it_tests():
    misplaced = [str(p.relative_to(TESTS)) for p in _test_files()
                 if p.parent != TESTS and p.relative_to(TESTS).parts[0] not in TEST_FOLDERS]
    gone = sorted(p.name for p in TESTS.iterdir() if p.is_dir() and p.name not in (*TEST_FOLDERS, HELPERS, "data", "__pycache__"))
    assert not gone, f"test folders named after no part of the package: {gone}"
    at_root = sorted(p.name for p in TESTS.glob("*.py") if p.name not in TEST_ROOT_FILES)
    assert not misplaced, f"test files outside {', '.join(TEST_FOLDERS)}: {misplaced}"
    assert not at_root, f"move into one of tests/{{{','.join(TEST_FOLDERS)}}}/: {at_root}"
    for folder in TEST_FOLDERS:
        assert any((TESTS / folder).rglob("test_*.py")), f"tests/{folder} holds no test"


def test_the_tests_are_packages_and_no_test_folder_is_on_the_pythonpath():
    # a test imports a helper by its package path (tests.support.faults), never by a bare name
    # that only resolves because its folder is on sys.path
    folders = {p.parent for p in TESTS.rglob("*.py") if "__pycache__" not in p.parts}
    assert folders >= {TESTS / f for f in (*TEST_FOLDERS, HELPERS)}
    not_packages = sorted(str(f.relative_to(ROOT)) for f in folders if not (f / "__init__.py").is_file())
    assert not not_packages, f"test folders without __init__.py: {not_packages}"
    ini = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["pytest"]["ini_options"]
    assert "pythonpath" not in ini
    assert not any((TESTS / HELPERS).glob("test_*.py"))
    bare = sorted({p.stem for p in TESTS.rglob("*.py")} - {"__init__", "conftest"})
    flat = []
    for path in sorted(TESTS.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            names = ([node.module] if isinstance(node, ast.ImportFrom) and not node.level
                     else [a.name for a in node.names] if isinstance(node, ast.Import) else [])
            flat += [f"{path.relative_to(ROOT)}:{node.lineno} {n}" for n in names
                     if n and n.split(".")[0] in (*bare, "conftest")]
    assert not flat, f"imports of a test module by its bare name: {flat}"


def test_the_markers_are_registered_strictly():
    ini = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["pytest"]["ini_options"]
    assert "--strict-markers" in ini["addopts"].split()
    assert sorted(m.split(":")[0] for m in ini["markers"]) == ["interop", "slow", "windows"]


@pytest.mark.slow  # a fresh interpreter: what importing the master loads, nothing loaded before it
def test_importing_the_master_loads_no_tapmp_module():
    import subprocess
    import sys
    code = ("import sys, orchestrator.engine.master\n"
            "print(' '.join(sorted(m for m in sys.modules if m == 'tapmp' or m.startswith('tapmp.'))))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    assert proc.stdout.split() == [], f"importing orchestrator.engine.master loads {proc.stdout.strip()}"


def test_no_layer_below_the_command_line_names_it_in_code():
    # an import is caught above; this catches a dotted name handed around as a string
    # ("orchestrator.cli.some_function") by which a lower layer would call up into the CLI
    named = []
    for layer in LAYERS:
        for path in sorted((PKG / layer).rglob("*.py")):
            tree = ast.parse(path.read_text(), str(path))
            docstrings = {id(n.body[0].value) for n in ast.walk(tree)
                          if isinstance(n, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
                          and n.body and isinstance(n.body[0], ast.Expr)
                          and isinstance(n.body[0].value, ast.Constant)}
            named += [f"{path.relative_to(ROOT)}:{n.lineno}" for n in ast.walk(tree)
                      if isinstance(n, ast.Constant) and isinstance(n.value, str) and id(n) not in docstrings
                      and "orchestrator.cli" in n.value]
    assert not named, f"below the command line, code names orchestrator.cli: {named}"


def _imported_by(package: str) -> set:
    """Every project module imported anywhere in ``package`` (module- and function-level)."""
    return {dep for module, deps in _imports().items() if _in(module, package) for dep in deps}


def test_the_tool_never_imports_the_paper_study():
    # a user who runs the tool for another controller needs none of the paper's modules: the
    # paper's printed rows reach comparison.md as data its callers pass in (reference_rows)
    tool_modules = [m for m in _imports() if _in(m, "orchestrator.tool")]
    assert len(tool_modules) > 20  # the walk sees the tool's modules
    assert not {d for d in _imported_by("orchestrator.tool") if _in(d, "orchestrator.paper")}
    assert {d for d in _imported_by("orchestrator.paper") if _in(d, "orchestrator.tool")}  # the paper builds on it
    paper = {p.stem for p in (PKG / "paper").glob("*.py")} - {"__init__"}
    assert {"reproduction", "paper_tables", "paper_gains", "calibration", "null_models", "predictors",
            "theorem1"} <= paper
    assert not paper & {p.stem for p in (PKG / "tool").glob("*.py")}


def test_the_compare_workflow_lives_in_the_tool():
    import inspect
    from orchestrator.cli import run as cli_run
    from orchestrator.tool import compare
    from orchestrator.paper import reproduction
    # the CLI and the reproduction call it downward; the reproduction is handed no compare function
    # (the CLI imports it where the command runs, so that --help loads no numerical package)
    assert "from ..tool.compare import run_comparison" in inspect.getsource(cli_run)
    assert not [p for p in (PKG / "cli").glob("*.py") if "def run_comparison" in p.read_text()]
    assert reproduction.run_comparison is compare.run_comparison
    assert "compare" not in inspect.signature(reproduction.reproduce).parameters
