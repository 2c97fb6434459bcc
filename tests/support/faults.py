"""Fault injection, in one place: the real pythonfmu plant with some of its methods overridden,
built into a real FMU, and an SSP of it with the real controller and trajectory.

The plant's adapter (``orchestrator.builder.build.adapter_script(PLANT)``) is copied with its class
renamed ``_RealPlant``, and a class ``TAPMP_Plant(_RealPlant)`` holding the given methods is
appended, so the faulty FMU has the real plant's interface, numbers and model description and
misbehaves only where a test says.

The ``faulty_ssps`` fixture (tests/conftest.py) builds :data:`FAULTY` once per session.
"""

from pathlib import Path

# The step that starts at t = 0.5 ms (5 steps of 0.1 ms) is the first faulty one; 4.5e-4, not
# 5e-4, so that a start time a rounding below 0.5 ms still counts.
FAULT_AT = 4.5e-4

# {fault: methods of TAPMP_Plant(_RealPlant)}: a plant that misbehaves from FAULT_AT on.
FAULTY = {
    "status": f'''
    def fmi2_do_step(self, current_time, step_size):
        status = super().fmi2_do_step(current_time, step_size)
        return 3 if current_time >= {FAULT_AT} else status  # fmi2Error, nothing logged
''',
    "error_log": f'''
    def step(self, t, h):
        super().step(t, h)
        if t >= {FAULT_AT}:
            self.log(f"encoder lost at t = {{t:.6g}} s", 3, "logStatusError")  # status stays fmi2OK
''',
    "info_log": f'''
    def step(self, t, h):
        super().step(t, h)
        if t >= {FAULT_AT}:
            self.log(f"step at t = {{t:.6g}} s", 0, "logAll")
''',
}


def faulty_plant_script(folder: Path, methods: str, doc: str = "The real plant, faulty.") -> Path:
    """Write ``folder/TAPMP_Plant.py``: the real plant's adapter as ``_RealPlant`` and a
    ``TAPMP_Plant(_RealPlant)`` with ``methods`` (source indented by four spaces) and the
    docstring ``doc``; returns its path."""
    from orchestrator.builder.build import adapter_script
    from tapmp.interface import PLANT

    real = adapter_script(PLANT).read_text().replace("class TAPMP_Plant(", "class _RealPlant(")
    real = real.replace("TAPMP_Plant.block(", "_RealPlant.block(")
    script = Path(folder) / "TAPMP_Plant.py"
    script.parent.mkdir(parents=True, exist_ok=True)
    script.write_text(real + f'\n\nclass TAPMP_Plant(_RealPlant):\n    """{doc}"""\n' + methods)
    return script


def faulty_plant_fmu(folder: Path, methods: str, doc: str = "The real plant, faulty.", binaries=None) -> Path:
    """The plant FMU of :func:`faulty_plant_script`, built into ``folder/fmus`` (the adapter in
    ``folder/src``); ``binaries`` from ``compile_binaries`` are reused if given."""
    from orchestrator.builder.build import build_fmu
    from tapmp.interface import PLANT

    script = faulty_plant_script(Path(folder) / "src", methods, doc)
    return build_fmu(PLANT, Path(folder) / "fmus", binaries=binaries, script=script)


def faulty_ssp(path: Path, plant: Path, built: dict) -> Path:
    """An SSP at ``path`` of the plant FMU ``plant`` with the real controller and trajectory of
    ``built`` (the session's pythonfmu FMUs)."""
    from orchestrator.builder.ssp import write_ssp
    from tapmp.interface import CONTROLLER, PLANT, TRAJECTORY

    return write_ssp(Path(path), {PLANT: plant, CONTROLLER: built[CONTROLLER], TRAJECTORY: built[TRAJECTORY]})


def faulty_ssps(built: dict, root: Path) -> dict:
    """{fault: SSP path} for every fault of :data:`FAULTY`, built under ``root``."""
    from orchestrator.builder.build import compile_binaries

    (root / "bin").mkdir(parents=True)
    binaries = compile_binaries(root / "bin")
    return {fault: faulty_ssp(root / fault / "system.ssp",
                              faulty_plant_fmu(root / fault, methods, binaries=binaries), built)
            for fault, methods in FAULTY.items()}
