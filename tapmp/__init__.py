"""TAPMP model core: plain, FMI-free Python for the three-axis parallel motion platform.

Everything here follows Zhou, Gao, Zhang, "Synchronization Control with Dynamics
Compensation for Three-Axis Parallel Motion Platform", Actuators 2024, 13, 166.
Units are SI throughout (m, rad, kg, N, s). Equation numbers refer to the paper.
The package needs only the Python standard library, so it runs inside any FMU host.
"""

__version__ = "0.1.0"
