"""A co-simulation's options are one frozen record (RunOptions) with a default for each; the master
refuses anything else in its place, and checks the values as it did its keyword arguments."""

import dataclasses

import pytest

from orchestrator.engine.master import CoSimulation, CoSimulationError, RunOptions


def test_the_options_are_one_frozen_record_with_a_default_for_each():
    options = RunOptions()
    assert (options.start_time, options.step_size, options.ordering, options.clock, options.connection_start,
            options.event_mode, options.model_exchange) == (0.0, 1e-4, "gauss-seidel", "exact", "propagated",
                                                            False, ())
    with pytest.raises(dataclasses.FrozenInstanceError):
        options.step_size = 1e-3
    changed = dataclasses.replace(options, step_size=1e-3)
    assert changed.step_size == 1e-3 and options.step_size == 1e-4


def test_the_master_takes_the_options_record_and_nothing_in_its_place(tmp_path):
    with pytest.raises(TypeError, match="options = 0.0 is invalid: allowed is a RunOptions"):
        CoSimulation(tmp_path / "x.ssp", {}, 0.0)  # the start time where the options go


@pytest.mark.parametrize("options, message", [
    (RunOptions(ordering="gauss"), "ordering = 'gauss' is invalid: allowed are gauss-seidel, jacobi"),
    (RunOptions(step_size=0.0), "step_size = 0.0 is invalid: allowed is a number > 0"),
    (RunOptions(ordering="jacobi", order=("plant",)), "order = ('plant',) is invalid with ordering = 'jacobi'"),
    (RunOptions(connection_start="late"), "connection_start = 'late' is invalid: allowed are propagated, zero"),
    (RunOptions(open_inputs="plant.F1"), "open_inputs = 'plant.F1' is invalid: allowed is a list of"),
], ids=["ordering", "step_size", "order", "connection_start", "open_inputs"])
def test_bad_options_are_refused_when_the_co_simulation_is_made(tmp_path, options, message):
    with pytest.raises(CoSimulationError, match=message.replace("(", r"\(").replace(")", r"\)")):
        CoSimulation(tmp_path / "x.ssp", {}, options)
