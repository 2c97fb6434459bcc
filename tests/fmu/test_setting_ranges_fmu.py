"""The FMUs refuse a setting with the C model's range checks: a rule no declared min/max can say
(the trajectory's |B_offset| + B_amplitude < pi/2) gives the same error and message in the
pythonfmu FMU, the native FMI 2.0 FMU and the Python model."""

import pytest

from tapmp.errors import ModelInputError
from tapmp.interface import TRAJECTORY
from tapmp.trajectory import TrajectoryParams

pytestmark = pytest.mark.slow  # builds every family


@pytest.mark.parametrize("family", ["python", "native"])
def test_a_b_sinusoid_beyond_the_kinematic_domain_is_refused_alike(built, native_built, load_fmu, family):
    with pytest.raises(ModelInputError) as err:
        TrajectoryParams(B_offset=1.0, B_amplitude=0.6).validated()
    fmu = load_fmu(built[TRAJECTORY] if family == "python" else native_built["fmi2"][TRAJECTORY])
    status = fmu.statuses(B_offset=1.0, B_amplitude=0.6)
    assert status["set"] == 0 and status["exitInitializationMode"] == 3, status
    assert any(str(err.value) in m for m in fmu.errors()), fmu.errors()
