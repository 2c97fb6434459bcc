"""Run an SSP in FMPy's `simulate_ssp` with parameters handed on as its parameter_set (fmpy 0.3.32
reads an SSP's parameter bindings but applies only that argument): the SSP's own bindings, or a
scenario's parameters with --scenario; prints the plant's final positions (m, m, rad).

    .venv/bin/python tests/interop/rows/fmpy_simulate_ssp.py results/export/paper.ssp --stop-time 0.2
    .venv/bin/python tests/interop/rows/fmpy_simulate_ssp.py build/TAPMP.ssp --stop-time 0.2 \
        --scenario scenarios/paper_simulation.toml
"""

import argparse
import sys
from pathlib import Path

from fmpy.ssp.simulation import simulate_ssp
from fmpy.ssp.ssd import Parameter, ParameterSet, read_ssd


def bound_parameters(ssp: Path) -> list[Parameter]:
    """The SSP's parameter bindings, named element.variable as simulate_ssp wants them."""
    return [Parameter(name=f"{c.name}.{p.name}", type=p.type, value=p.value)
            for c in read_ssd(str(ssp)).system.elements for b in c.parameterBindings
            for s in b.parameterValues for p in s.parameters]


def scenario_parameters(toml: Path) -> list[Parameter]:
    """The scenario's parameters (the FMUs' parameters it sets), named element.variable."""
    from orchestrator.tool.scenario import load
    scenario = load(toml)
    return [Parameter(name=f"{element}.{name}", value=value)
            for element, table in scenario.parameters().items() for name, value in table.items()]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("ssp", type=Path, help="the SSP file")
    p.add_argument("--stop-time", type=float, default=0.2, help="s")
    p.add_argument("--step-size", type=float, default=1e-4, help="s")
    p.add_argument("--scenario", type=Path, help="a scenario TOML whose parameters to apply instead of the bindings")
    args = p.parse_args(argv)
    if not args.ssp.is_file():
        p.error(f"ssp = {str(args.ssp)!r} is not a file: give the path of an .ssp file")
    parameters = scenario_parameters(args.scenario) if args.scenario else bound_parameters(args.ssp)
    r = simulate_ssp(str(args.ssp), stop_time=args.stop_time, step_size=args.step_size,
                     parameter_set=ParameterSet(name="parameters", parameters=parameters))
    print([float(r[f"plant.q{i}_true"][-1]) for i in (1, 2, 3)])
    return 0


if __name__ == "__main__":
    sys.exit(main())
