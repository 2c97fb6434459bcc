"""One range rule per setting, refused alike everywhere: walking the settings table
(tapmp.interface), a value just outside each parameter's range gets the same one-line refusal
naming the setting from the Python model, the pythonfmu FMU, the native FMI 2.0 and FMI 3.0
FMUs (through fmpy) and, exit code 2, from `tapmp check` and `tapmp run`. The rule no declared
min/max can say (the trajectory's |B_offset| + B_amplitude < pi/2) is refused alike too."""

from pathlib import Path

import pytest
from fmpy import simulate_fmu

from orchestrator.cli import main
import ctoolchain as toolchain
from tapmp import cmodel
from tapmp.errors import ModelInputError
from tapmp.interface import TRAJECTORY, VARIABLES, allowed_text
from tapmp.trajectory import TrajectoryParams

pytestmark = pytest.mark.slow  # builds every family

PAPER = Path(__file__).resolve().parents[2] / "scenarios" / "paper_simulation.toml"
SETTINGS = [(model, v) for model, table in VARIABLES.items() for v in table if v.causality == "parameter"]


def outside(v):
    """A value just outside the range of ``v``: below an Integer's min, 1 % above a Real's max."""
    return int(v.min) - 1 if v.type == "Integer" else v.max * 1.01


def refusal(v) -> str:
    return f"{v.name} = {outside(v)!r} is invalid: allowed is {allowed_text(v)}"


@pytest.fixture(scope="module")
def families(built, tmp_path_factory):
    """{family: {model: FMU path}}: pythonfmu and the native FMI 2.0 and 3.0 FMUs for this host."""
    from orchestrator.builder.build_native import build_native
    native_fmus = build_native(tmp_path_factory.mktemp("native"), log=lambda *_: None,
                               platforms=(toolchain.HOST,))
    return {"python": built, **native_fmus}


def fmu_errors(path, start_values) -> list[str]:
    """The error messages of one run of the FMU at ``path`` with ``start_values`` (fmpy
    simulate_fmu, one step), which must fail."""
    messages = []

    def logger(*args):  # FMI 2.0 and 3.0 loggers differ in their leading arguments
        status, message = args[-3], args[-1]
        if status >= 3:
            messages.append(message.decode())
    with pytest.raises(Exception):
        simulate_fmu(str(path), start_values=start_values, stop_time=1e-4, output_interval=1e-4,
                     logger=logger, validate=False)
    return messages


@pytest.mark.parametrize("model, v", SETTINGS, ids=[f"{m}.{v.name}" for m, v in SETTINGS])
def test_a_setting_outside_its_range_is_refused_alike_by_the_model_and_every_family(families, model, v):
    with pytest.raises(ModelInputError) as err:
        cmodel.check_settings(model, {v.name: outside(v)})
    assert str(err.value) == refusal(v)
    for family, fmus in families.items():
        errors = fmu_errors(fmus[model], {v.name: outside(v)})
        assert any(m.startswith(refusal(v)) for m in errors), (family, errors)


@pytest.mark.parametrize("command", ["check", "run"])
@pytest.mark.parametrize("setting, name", [("gain_overrides.D=2e9", "gain_overrides.D1"),
                                           ("plant.k_pull=2e12", "plant.k_pull"),
                                           ("trajectory.B_b=1.6", "trajectory.B_b")])
def test_the_command_refuses_a_setting_outside_its_range_with_one_line_and_exit_2(tmp_path, capsys, command,
                                                                                setting, name):
    from tapmp.interface import CONTROLLER, PLANT
    model = {"gain_overrides": CONTROLLER, "plant": PLANT, "trajectory": TRAJECTORY}[name.split(".")[0]]
    v = next(v for v in VARIABLES[model] if v.name == name.split(".")[1])
    value = float(setting.split("=")[1])
    args = ["--out", str(tmp_path / "r"), "--no-progress"] if command == "run" else []
    code = main([command, str(PAPER), "--set", setting, *args])
    err = capsys.readouterr().err
    assert (code, err) == (2, f"error: {name} = {value!r} is invalid: allowed is {allowed_text(v)}\n")


@pytest.mark.parametrize("family", ["python", "fmi2", "fmi3"])
def test_a_b_sinusoid_beyond_the_kinematic_domain_is_refused_alike(families, family):
    with pytest.raises(ModelInputError) as err:
        TrajectoryParams(B_offset=1.0, B_amplitude=0.6).validated()
    errors = fmu_errors(families[family][TRAJECTORY], {"B_offset": 1.0, "B_amplitude": 0.6})
    assert any(m.startswith(str(err.value)) for m in errors), errors


@pytest.mark.parametrize("family", ["python", "fmi2", "fmi3"])
def test_an_anti_windup_without_a_controller_force_limit_is_refused_alike(families, family):
    from tapmp.interface import CONTROLLER
    with pytest.raises(ModelInputError) as err:
        cmodel.check_settings(CONTROLLER, {"anti_windup": 2, "force_limit": 0.0})
    assert str(err.value).startswith("anti_windup = 2 is invalid: allowed is 0 (off) while force_limit = 0")
    errors = fmu_errors(families[family][CONTROLLER], {"anti_windup": 2, "force_limit": 0.0})
    assert any(m.startswith(str(err.value)) for m in errors), errors
