"""TAPMP model core: plain, FMI-free Python for the three-axis parallel motion platform.

Everything here follows Zhou, Gao, Zhang, "Synchronization Control with Dynamics
Compensation for Three-Axis Parallel Motion Platform", Actuators 2024, 13, 166.
Units are SI throughout (m, rad, kg, N, s). Equation numbers refer to the paper.
The equations are computed by the C model tapmp/c/tapmp_model.c (loaded through cffi,
tapmp.cmodel), the code every FMU family runs; the Python modules write them readably.
"""

__version__ = "0.1.0"

# The models' records (tapmp.models.MODELS), filled once, before any module reads them.
from . import records  # noqa: E402,F401
