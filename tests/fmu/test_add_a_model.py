"""A new model added the way docs/architecture.md ("Adding a model") says: its C file and header, its
record, nothing else. The test model is a gain block TAPMP_Gain (input u [m], output y = k u [m],
parameter k), fed by the plant's q1 in the SSP system. Its record is registered the way tapmp/records.py
registers the TAPMP models (tapmp.models.register), its C files are written to a temporary folder
(a record's paths may be absolute), and it is removed from the registry after each test."""

import re

import numpy as np
import pytest

from tapmp.interface import Dependencies, Var, dependencies
from tapmp.models import PLANT, ModelRecord, models_table, register, unregister

GAIN = "TAPMP_Gain"
K = 2.5

# Step 1 of the recipe: the model's header (its data, the block of outputs) ...
GAIN_H = """/* Model data of the TAPMP_Gain FMU (gain.c): y = k u. */
#ifndef TAPMP_GAIN_FMU_H
#define TAPMP_GAIN_FMU_H
typedef struct { int unused; } ModelData;
#define MODEL_N_HIDDEN 0
#define MODEL_N_OUT 1
#define MODEL_OUT_FIRST VR_y
#endif
"""
# ... and its C file: the model functions the runtime calls (fmu_common/c/instance.h). The range of k is
# the runtime's check of the record's min/max; the output changes only in doStep and initially.
GAIN_C = """/* Native TAPMP_Gain FMU: y = k u, sampled at each communication point and held over the step. */
#include "instance.h"

int model_validate(const tapmp_instance *inst, char *msg, size_t size)
{
    (void)inst, (void)msg, (void)size;
    return 1;
}

static double gain(const tapmp_instance *inst) { return inst->reals[VR_k] * inst->reals[VR_u]; }

void model_setup(tapmp_instance *inst) { inst->reals[VR_y] = gain(inst); }

int model_initial_outputs(tapmp_instance *inst, char *msg, size_t size)
{
    (void)msg, (void)size;
    inst->reals[VR_y] = gain(inst);
    return 1;
}

int model_step(tapmp_instance *inst, double t, double h, double out[], char *msg, size_t size)
{
    (void)t, (void)h, (void)msg, (void)size;
    out[0] = gain(inst);
    return 1;
}

void model_get_hidden(const tapmp_instance *inst, double hidden[]) { (void)inst, (void)hidden; }

void model_set_hidden(tapmp_instance *inst, const double hidden[]) { (void)inst, (void)hidden; }

int model_check_hidden(const tapmp_instance *state, const double hidden[], char *msg, size_t size)
{
    (void)state, (void)hidden, (void)msg, (void)size;
    return 1;
}
"""


def gain_record(folder) -> ModelRecord:
    """Step 2 of the recipe: the model's record."""
    return ModelRecord(
        name=GAIN, element="gain",
        variables=(Var("u", "input", "m", "signal in"),
                   Var("y", "output", "m", "k u, held over the communication step"),
                   Var("k", "parameter", "1", "gain", K, variability="fixed", min=-1e6, max=1e6)),
        dependencies=lambda output: Dependencies((), ("u", "k")),
        sources={"u": (PLANT, "q1")},
        source=str(folder / "gain.c"), header=str(folder / "gain.h"),
        description="Gain block y = k u (native C, no Python at run time)",
        what="A gain block: y = k u.", equations=(("Gain", "y = k u"),), icon_label="k", diagram_note="y = k u")


@pytest.fixture
def gain_model(tmp_path):
    folder = tmp_path / "fmu_gain"
    folder.mkdir()
    (folder / "gain.h").write_text(GAIN_H)
    (folder / "gain.c").write_text(GAIN_C)
    record = register(gain_record(folder))
    yield record
    unregister(GAIN)


def test_a_registered_model_appears_in_the_builders_the_docs_table_and_the_ssp_writer(gain_model):
    from orchestrator.builder.build import python_models
    from orchestrator.builder.build_native import (model_description_fmi2, model_description_fmi3, native_models,
                                                   source_files)
    from orchestrator.builder.fmu_extras import diagram_svg, documentation_html
    from orchestrator.builder.ssp import system_structure

    assert native_models("fmi2")[-1] == native_models("fmi3")[-1] == GAIN
    assert GAIN not in python_models()  # no pythonfmu twin: the record names no adapter
    for md in (model_description_fmi2(GAIN), model_description_fmi3(GAIN)):
        assert f'modelName="{GAIN}"'.encode() in md and b'name="k"' in md
    assert "gain.c" in source_files(GAIN, "fmi2")
    assert dependencies(GAIN) == {"y": Dependencies((), ("u", "k"))}
    assert f"| `{GAIN}` | `gain` |" in models_table()
    ssd = system_structure().decode()
    assert f'<ssd:Component name="gain" type="application/x-fmu-sharedlibrary" source="resources/{GAIN}.fmu">' in ssd
    assert ('<ssd:Connection startElement="plant" startConnector="q1" endElement="gain" endConnector="u" />'
            in ssd)
    svg = diagram_svg(GAIN).decode()
    assert len(re.findall("<rect x=", svg)) == 4 and f">{GAIN}</text>" in svg
    assert "y = k u" in documentation_html(GAIN, "fmi3").decode()


@pytest.mark.slow  # compiles four native FMUs and runs their reference experiments
def test_a_model_added_by_the_recipe_builds_validates_and_runs_in_the_ssp(gain_model, tmp_path):
    from fmpy.validation import validate_fmu

    from ctoolchain import HOST
    from orchestrator.builder.build_native import build_native, build_native_fmu
    from orchestrator.engine.master import CoSimulation

    # Step 3 of the recipe: build. The system's SSP is written with the new element, wired by its record.
    paths = build_native(tmp_path / "native", families=("fmi2",), platforms=(HOST,), log=lambda *_: None)["fmi2"]
    (tmp_path / "fmi3").mkdir()
    fmi3 = build_native_fmu(GAIN, "fmi3", tmp_path / "fmi3", platforms=(HOST,))
    for fmu in (paths[GAIN], fmi3):
        assert validate_fmu(str(fmu)) == []
    steps = 100
    with CoSimulation(paths["ssp"], {}) as sim:
        rows = np.empty((steps, len(sim.columns)))
        sim.advance(rows)
        column = {name: i for i, name in enumerate(sim.columns)}
    q1, y = rows[:, column["plant.q1"]], rows[:, column["gain.y"]]
    assert np.any(q1 != 0.0)  # the plant moves, so the gain's output says something
    # each row is the end of a step from t to t + h: the gain's y is k times the q1 it read at t (the row
    # before; q1 starts at 0), held over the step as its record's dependencies say
    assert y[0] == 0.0 and np.array_equal(y[1:], K * q1[:-1])
