"""The command line as a package: one module per command group, none over 450 lines, and one base
of the user errors, which the command catches (it names no error class one by one); an error of the
lowest package still prints as one line, exit 2."""

import ast
import importlib
from pathlib import Path

import pytest

from ctoolchain.errors import UserError
from orchestrator import cli

CLI = Path(cli.__file__).parent
MAX_LINES = 450

# The project's user-facing error types, each with the built-in type its callers catch, from every
# layer: the toolchain, the model, the engine, the builder, the tool, the studies.
USER_ERROR_TYPES = [
    ("ctoolchain:CacheTrustError", RuntimeError),
    ("tapmp.errors:ModelInputError", ValueError),
    ("tapmp.errors:KinematicDomainError", ValueError),
    ("tapmp.cmodel:CModelError", RuntimeError),
    ("orchestrator.errors:UsageError", ValueError),
    ("orchestrator.engine.errors:CoSimulationError", RuntimeError),
    ("orchestrator.engine.errors:DivergenceError", RuntimeError),
    ("orchestrator.engine.schedule:ScheduleError", ValueError),
    ("orchestrator.engine.ssd:ParameterAddressError", ValueError),
    ("orchestrator.builder.build:BuildError", RuntimeError),
    ("orchestrator.builder.build_native:NativeBuildError", RuntimeError),
    ("orchestrator.tool.export:ExportError", ValueError),
    ("orchestrator.tool.folders:OutputExistsError", RuntimeError),
    ("orchestrator.tool.folders:OutputInUseError", RuntimeError),
    ("orchestrator.tool.folders:ResultsWriteError", RuntimeError),
    ("orchestrator.tool.reading:ResultFolderError", ValueError),
    ("orchestrator.tool.scenario:ScenarioError", ValueError),
    ("orchestrator.studies.study_file:StudyError", ValueError),
]


def test_no_module_of_the_command_line_is_over_450_lines():
    lengths = {p.name: len(p.read_text().splitlines()) for p in sorted(CLI.glob("*.py"))}
    assert {"__init__.py", "options.py", "signals.py", "run.py", "study.py"} <= set(lengths)
    assert not {name: n for name, n in lengths.items() if n > MAX_LINES}


def test_the_command_line_catches_the_base_and_names_no_error_class():
    assert cli.USER_ERRORS == (UserError, OSError)
    ours = {where.split(":")[1] for where, _ in USER_ERROR_TYPES}
    listed = []  # a tuple naming two or more of the project's error types, as a list of user errors would
    for path in sorted(CLI.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Tuple):
                names = [e.id if isinstance(e, ast.Name) else getattr(e, "attr", "") for e in node.elts]
                if len(ours.intersection(names)) > 1:
                    listed.append(f"{path.name}:{node.lineno} {', '.join(names)}")
    assert not listed, listed


@pytest.mark.parametrize("where, builtin", USER_ERROR_TYPES, ids=[w for w, _ in USER_ERROR_TYPES])
def test_every_user_error_type_derives_from_the_base_and_keeps_its_builtin_type(where, builtin):
    module, name = where.split(":")
    cls = getattr(importlib.import_module(module), name)
    assert issubclass(cls, UserError) and issubclass(cls, builtin)
    assert issubclass(cls, cli.USER_ERRORS)


def test_an_error_of_the_lowest_package_is_one_line_exit_2(tmp_path, monkeypatch, capsys):
    # ctoolchain's CacheTrustError: a cache folder anyone may write is refused before anything is built
    cache = tmp_path / "cache"
    cache.mkdir()
    cache.chmod(0o777)
    monkeypatch.setenv("TAPMP_CACHE", str(cache))
    assert cli.main(["build", "--clean-cache", "--out", str(tmp_path / "fmus")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: the compiled-code cache: {cache} is writable by") and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "fmus").exists()
