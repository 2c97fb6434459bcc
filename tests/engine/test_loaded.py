"""FMUs kept loaded between co-simulations (orchestrator/engine/loaded.py): a co-simulation on
instances that were reset (fmi2Reset / fmi3Reset) and reused gives the rows of one on new
instances, bit for bit, after any earlier case (other parameters, a diverged run, a failed FMU
call); an instance whose reset fails is replaced by a new one; the extracted files go away."""

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from tests.support.runs import paper_scenario
from orchestrator.engine.loaded import LoadedFMUs
from orchestrator.engine.master import CoSimulation, CoSimulationError, DivergenceError, RunOptions
from orchestrator.tool.envelope import envelope
from orchestrator.tool.roles import ROLES, SCENARIO_TABLES

ROOT = Path(__file__).resolve().parents[2]


def family_ssp(family, built, native_built):
    return built["ssp"] if family == "pythonfmu" else native_built[family]["ssp"]


def run(ssp, parameters, scenario, loaded=None, steps=500):
    """(columns, rows of ``steps`` steps after row 0, GUIDs) of one co-simulation."""
    with CoSimulation(ssp, parameters, RunOptions(start_time=scenario.start_time, step_size=scenario.step,
                                                  ordering=scenario.ordering, check=envelope(scenario), roles=ROLES,
                                                  other_tables=SCENARIO_TABLES), loaded=loaded) as sim:
        rows = np.empty((steps + 1, len(sim.columns)))
        rows[0] = sim.row()
        sim.advance(rows[1:])
        return sim.columns, rows, dict(sim.guids)


def same_bits(a, b) -> bool:
    return a.shape == b.shape and a.tobytes() == b.tobytes()


@pytest.mark.parametrize("family", ["fmi2", "fmi3", "pythonfmu"])
def test_reset_and_reused_instances_give_the_rows_of_new_instances_bit_for_bit(family, built, native_built):
    ssp, base = family_ssp(family, built, native_built), paper_scenario(0.05)
    other = paper_scenario(0.05, "gain_overrides.D=450", "gain_overrides.Lambda_v=1.44", "plant.c_v1=30")
    loaded = LoadedFMUs()
    try:
        run(ssp, other.parameters(), other, loaded)
        # no parameter set at all: every variable must be back at its start value after the reset
        cols, start_values, _ = run(ssp, {}, base, loaded)
        _, fresh_start_values, _ = run(ssp, {}, base)
        assert same_bits(start_values, fresh_start_values)
        cols, reused, guids = run(ssp, base.parameters(), base, loaded)
        _, fresh, fresh_guids = run(ssp, base.parameters(), base)
        assert same_bits(reused, fresh) and guids == fresh_guids
        assert loaded.counts == {"loaded": 1, "reused": 2, "reset": 9, "replaced": 0}
    finally:
        loaded.close()
    # the cases differ: the reuse had something to undo
    _, first, _ = run(ssp, other.parameters(), other)
    assert not same_bits(first, fresh) and np.ptp(fresh[:, cols.index("plant.X")]) > 1e-4


@pytest.mark.parametrize("family", ["fmi2", "fmi3"])
def test_a_case_after_a_diverged_case_on_the_same_instances_gives_a_fresh_cases_rows(family, native_built):
    ssp, good = native_built[family]["ssp"], paper_scenario(0.05)
    bad = paper_scenario(0.05, 'gains="paper_simulation"', "plant.force_limit=0", "limits.motor_travel=0.001")
    loaded = LoadedFMUs()
    try:
        with pytest.raises(DivergenceError, match="is outside the envelope"):
            run(ssp, bad.parameters(), bad, loaded)
        _, reused, _ = run(ssp, good.parameters(), good, loaded)
        assert loaded.counts["reused"] == 1 and loaded.counts["replaced"] == 0
    finally:
        loaded.close()
    _, fresh, _ = run(ssp, good.parameters(), good)
    assert same_bits(reused, fresh)


def test_a_case_after_a_failed_fmu_call_on_the_same_instances_gives_a_fresh_cases_rows(faulty_ssps):
    ssp, sc = faulty_ssps["status"], paper_scenario(0.05)  # the plant returns fmi2Error from t = 0.5 ms on
    loaded = LoadedFMUs()
    try:
        with pytest.raises(CoSimulationError, match="plant: doStep failed at t = 0.0005 s"):
            run(ssp, sc.parameters(), sc, loaded)
        _, reused, _ = run(ssp, sc.parameters(), sc, loaded, steps=4)  # the steps before the fault
        assert loaded.counts["reused"] == 1 and loaded.counts["replaced"] == 0
    finally:
        loaded.close()
    _, fresh, _ = run(ssp, sc.parameters(), sc, steps=4)
    assert same_bits(reused, fresh)


def test_a_refused_parameter_leaves_the_instances_reusable(native_built):
    ssp, sc = native_built["fmi2"]["ssp"], paper_scenario(0.05)
    loaded = LoadedFMUs()
    try:
        with pytest.raises(CoSimulationError, match="plant.mass is not a parameter of TAPMP_Plant"):
            run(ssp, {"plant": {"mass": 1.0}}, sc, loaded)
        _, reused, _ = run(ssp, sc.parameters(), sc, loaded)
        assert loaded.counts["reused"] == 1
    finally:
        loaded.close()
    _, fresh, _ = run(ssp, sc.parameters(), sc)
    assert same_bits(reused, fresh)


def test_another_ssp_written_to_the_same_path_gets_its_own_fmus(native_built, tmp_path):
    ssp, sc = tmp_path / "TAPMP.ssp", paper_scenario(0.05)
    loaded = LoadedFMUs()
    try:
        shutil.copyfile(native_built["fmi2"]["ssp"], ssp)
        run(ssp, sc.parameters(), sc, loaded)
        shutil.copyfile(native_built["fmi3"]["ssp"], ssp)
        _, rows, guids = run(ssp, sc.parameters(), sc, loaded)
        assert loaded.counts["loaded"] == 2 and loaded.counts["reused"] == 0
    finally:
        loaded.close()
    _, fresh, fresh_guids = run(native_built["fmi3"]["ssp"], sc.parameters(), sc)
    assert same_bits(rows, fresh) and guids == fresh_guids


def test_closing_frees_the_instances_and_removes_the_extracted_files(native_built):
    ssp, sc = native_built["fmi2"]["ssp"], paper_scenario(0.01)
    loaded = LoadedFMUs()
    with CoSimulation(ssp, sc.parameters(), RunOptions(roles=ROLES, other_tables=SCENARIO_TABLES),
                      loaded=loaded) as sim:
        folder, units = sim.tmp, list(sim.units.values())
    assert folder.is_dir() and all(u.instantiated for u in units)  # kept, reset, for the next case
    loaded.close()
    assert not folder.exists() and not any(u.instantiated for u in units)
    # a system given back after the close is closed at once
    with CoSimulation(ssp, sc.parameters(), RunOptions(roles=ROLES, other_tables=SCENARIO_TABLES),
                      loaded=loaded) as sim:
        folder = sim.tmp
    assert not folder.exists()


def test_a_worker_process_removes_its_loaded_fmus_folder_when_it_exits(native_built, tmp_path):
    code = ("import sys\nfrom orchestrator.engine.loaded import process_fmus\n"
            "from orchestrator.engine.master import CoSimulation\n"
            "with CoSimulation(sys.argv[1], {}, loaded=process_fmus()) as sim:\n    print(sim.tmp)\n")
    proc = subprocess.run([sys.executable, "-c", code, str(native_built["fmi2"]["ssp"])], capture_output=True,
                          text=True, timeout=120, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    folder = Path(proc.stdout.strip())
    assert folder.name.startswith("tapmp_cosim_") and not folder.exists()


# A trajectory FMU on pythonfmu 0.7's own binary (its fmi2Reset constructs the Python object
# again): the interface of TAPMP_Trajectory, outputs held at their start values, and a
# constructor that raises after an instance of the process stepped without being terminated,
# so fmi2Reset after a case fails while fmi2Instantiate after fmi2Terminate works.
REFUSING = '''
_STEPPED = []


class Refusing_Trajectory(Fmi2Slave):
    """TAPMP_Trajectory's interface, outputs at their start values; fmi2Reset after a step fails."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        if _STEPPED:
            _STEPPED.clear()
            raise RuntimeError("this FMU cannot be reset after a step")
        register_interface(self, "TAPMP_Trajectory")

    def terminate(self):
        _STEPPED.clear()

    def do_step(self, current_time, step_size):
        _STEPPED.append(current_time)
        return True
'''

# In child processes: pythonfmu's binary turns the Python exception into fmi2Fatal, after which
# FMI allows no call on any instance of that FMU in the process; the fresh run has its own.
RUN_CASES = '''
import hashlib, json, sys
import numpy as np
from orchestrator.engine.loaded import LoadedFMUs
from orchestrator.engine.master import CoSimulation, RunOptions

def rows(loaded=None):
    with CoSimulation(sys.argv[1], {}, loaded=loaded) as sim:
        out = np.empty((100, len(sim.columns)))
        sim.advance(out)
        errors = [m for m in sim.log if m.startswith(("[ERROR]", "[FATAL]"))]
        return hashlib.sha256(out.tobytes()).hexdigest(), errors

if sys.argv[2] == "fresh":
    print(json.dumps({"rows": [rows()[0]]}))
else:
    loaded = LoadedFMUs()
    first, _ = rows(loaded)
    after_first = dict(loaded.counts)
    second, errors = rows(loaded)
    after_second = dict(loaded.counts)
    loaded.close()
    print(json.dumps({"after_first": after_first, "after_second": after_second, "errors": errors,
                      "rows": [first, second]}), flush=True)
    # pythonfmu 0.7's binary, once it has returned fmi2Fatal, crashes some interpreter exits (its own
    # objects outlive Python's); the outcome is printed, so end without the interpreter's teardown
    import os
    os._exit(0)
'''


def test_an_instance_whose_reset_fails_is_replaced_by_a_new_one(native_built, tmp_path):
    from orchestrator.builder.build import build_interface_fmu
    from orchestrator.builder.ssp import write_ssp
    from tapmp.interface import CONTROLLER, PLANT, TRAJECTORY
    trajectory = build_interface_fmu(tmp_path / "src" / "Refusing_Trajectory.py", REFUSING, tmp_path)
    with zipfile.ZipFile(native_built["fmi2"]["ssp"]) as z:
        fmus = {m: Path(z.extract(f"resources/{m}.fmu", tmp_path / "native")) for m in (PLANT, CONTROLLER)}
    ssp = write_ssp(tmp_path / "refusing.ssp", {**fmus, TRAJECTORY: trajectory})
    out = {}
    for mode in ("fresh", "cached"):
        proc = subprocess.run([sys.executable, "-c", RUN_CASES, str(ssp), mode], capture_output=True, text=True,
                              timeout=300, cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)})
        assert proc.returncode == 0, proc.stderr
        out[mode] = json.loads(proc.stdout.splitlines()[-1])
    cached = out["cached"]
    # the trajectory's reset failed after each case and only its instance was replaced
    assert cached["after_first"] == {"loaded": 1, "reused": 0, "reset": 2, "replaced": 1}
    assert cached["after_second"] == {"loaded": 1, "reused": 1, "reset": 4, "replaced": 2}
    # the second case ran on a new trajectory instance, logged no error and gave a fresh run's rows
    assert cached["errors"] == [] and cached["rows"] == out["fresh"]["rows"] * 2


def test_an_fmu_kept_loaded_logs_into_its_own_run_after_other_runs_came_and_went(faulty_ssps):
    import gc
    ssp, sc = faulty_ssps["error_log"], paper_scenario(0.05)  # the plant logs an error from t = 0.5 ms on
    loaded = LoadedFMUs()
    try:
        run(ssp, sc.parameters(), sc, loaded, steps=4)  # kept, reset
        for _ in range(3):  # runs on FMUs of their own, loaded and freed
            run(ssp, sc.parameters(), sc, steps=4)
        gc.collect()
        with pytest.raises(CoSimulationError, match="encoder lost at t = 0.0005 s") as info:
            run(ssp, sc.parameters(), sc, loaded)
        assert loaded.counts["reused"] == 1 and any("encoder lost" in m for m in info.value.log)
    finally:
        loaded.close()
