"""fmu_common/binding.py: each FMU runs its own adapter code, even when two FMUs in one
process have adapters of the same module name."""

import pytest

from orchestrator.builder.build import build_fmu
from tapmp.interface import PLANT

FROZEN_PLANT = '''
from fmu_common.slave import TapmpSlave
from tapmp.interface import PLANT_VARS


class TAPMP_Plant(TapmpSlave):
    """Same name and interface as the real plant, but it never moves."""
    VARIABLES = PLANT_VARS

    def setup_model(self):
        pass

    def step(self, t, h):
        pass
'''


@pytest.mark.slow
def test_two_fmus_with_the_same_adapter_name_run_their_own_code(built, load_fmu, tmp_path):
    script = tmp_path / "src" / "TAPMP_Plant.py"
    script.parent.mkdir()
    script.write_text(FROZEN_PLANT)
    frozen_path = build_fmu(PLANT, tmp_path / "frozen", script=script)
    real, frozen = load_fmu(built[PLANT]), load_fmu(frozen_path)
    for fmu in (real, frozen):
        fmu.init(F1=50.0, F2=50.0, F3=50.0)
        for k in range(10):
            fmu.slave.doStep(k * 1e-4, 1e-4)
    assert real.get("q1_true")[0] > 1e-7     # the real plant was pushed along X
    assert frozen.get("q1_true")[0] == 0.0   # the frozen one kept its start value
    real.slave.doStep(1e-3, 1e-4)            # and loading the second did not replace the first
    assert real.get("q1_true")[0] > 1e-7
