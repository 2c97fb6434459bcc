"""A scenario's run options are built in one place (results.run_options): every scenario key the
master reads reaches it, with the TAPMP roles, the scenario tables and the platform envelope."""

from pathlib import Path

from orchestrator.tool.envelope import envelope
from orchestrator.tool.results import run_options
from orchestrator.tool.roles import ROLES, SCENARIO_TABLES
from orchestrator.tool.scenario import load

PAPER = Path(__file__).resolve().parents[3] / "scenarios" / "paper_simulation.toml"


def test_every_scenario_key_the_master_reads_reaches_its_options():
    sc = load(PAPER, ["start_time=0.5", "stop_time=0.6", "step=2e-4", 'ordering="jacobi"', 'clock="accumulated"',
                      'connection_start="zero"', 'plant_interface="me"'])
    o = run_options(sc)
    assert (o.start_time, o.step_size, o.ordering, o.order, o.clock, o.connection_start, o.event_mode) == \
        (0.5, 2e-4, "jacobi", None, "accumulated", "zero", False)
    assert o.model_exchange == ("plant",) and tuple(o.open_inputs) == tuple(sc.open_inputs)
    assert dict(o.roles) == ROLES and tuple(o.other_tables) == tuple(SCENARIO_TABLES)
    assert o.check.bounds == envelope(sc).bounds and o.check.bounds
    assert run_options(load(PAPER)).model_exchange == ()  # the plant as Co-Simulation FMU by default
