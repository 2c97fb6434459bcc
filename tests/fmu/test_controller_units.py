"""The controller's units and descriptions, read back from every family's modelDescription.xml
(pythonfmu, native FMI 2.0, native FMI 3.0): what tapmp/interface.py defines, and physically
honest: the law works in command units u with K_T F = u, so each gain divided by K_T is a
force gain in N/m, N s/m or N/(m s), and u / K_T is a force in N.
"""

import re

import pytest
from fmpy import read_model_description

from tapmp.interface import CONTROLLER, FMU_NAMES, UNITS, VARIABLES

FAMILIES = ("python", "fmi2", "fmi3")
SI = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")


@pytest.fixture(scope="module")
def descriptions(built, native_built):
    paths = {"python": built, "fmi2": native_built["fmi2"], "fmi3": native_built["fmi3"]}
    return {f: {m: read_model_description(str(paths[f][m])) for m in FMU_NAMES} for f in FAMILIES}


def _exponents(md, unit: str) -> dict:
    """SI base-unit exponents of ``unit`` as the modelDescription's UnitDefinitions give them."""
    (u,) = [u for u in md.unitDefinitions if u.name == unit]
    base = u.baseUnit
    return {k: getattr(base, k) for k in SI if base is not None and getattr(base, k, 0)}


def _ratio(a: dict, b: dict) -> dict:
    keys = set(a) | set(b)
    return {k: a.get(k, 0) - b.get(k, 0) for k in keys if a.get(k, 0) != b.get(k, 0)}


@pytest.mark.parametrize("family", FAMILIES)
def test_controller_variables_read_back_as_defined(descriptions, family):
    md = descriptions[family][CONTROLLER]
    got = {v.name: v for v in md.modelVariables if v.name != "time"}
    assert list(got) == [v.name for v in VARIABLES[CONTROLLER]]
    for var in VARIABLES[CONTROLLER]:
        mv = got[var.name]
        assert mv.description == var.description, var.name
        assert (mv.unit or "") == (var.unit if var.type == "Real" else ""), var.name
        if var.type == "Real" and var.unit:
            assert _exponents(md, var.unit) == {k: e for k, e in UNITS[var.unit].items() if e}, var.unit


@pytest.mark.parametrize("family", FAMILIES)
def test_gains_over_K_T_are_force_gains(descriptions, family):
    """Dimensional check on the units as written: Lambda_p/K_T in N/m, Lambda_v/K_T in N s/m,
    the modal gains / K_T in N/m, N s/m, N/(m s), u/K_T in N = F's unit; and every gain's
    description names its force gain."""
    md = descriptions[family][CONTROLLER]
    unit = {v.name: v.unit for v in md.modelVariables}
    N, N_m, Ns_m, N_ms = ({"kg": 1, "m": 1, "s": -2}, {"kg": 1, "s": -2}, {"kg": 1, "s": -1}, {"kg": 1, "s": -3})
    for i in (1, 2, 3):
        K_T = _exponents(md, unit[f"K_T{i}"])
        assert _ratio(_exponents(md, unit[f"Lambda_p{i}"]), K_T) == N_m
        assert _ratio(_exponents(md, unit[f"Lambda_v{i}"]), K_T) == Ns_m
        assert _ratio(_exponents(md, unit[f"u{i}"]), K_T) == N == _exponents(md, unit[f"F{i}"])
    for mode in "cd":
        K_T = _exponents(md, unit["K_T1"])
        for k, force in (("p", N_m), ("v", Ns_m), ("i", N_ms)):
            assert _ratio(_exponents(md, unit[f"k{k}_{mode}"]), K_T) == force
    text = {v.name: v.description for v in md.modelVariables}
    assert "the force gain (damping) is Lambda_v1/K_T1 N.s/m" in text["Lambda_v1"]
    assert "the force gain is Lambda_p2/K_T2 N/m" in text["Lambda_p2"]
    assert "the force gain is ki_d/K_T N/(m.s)" in text["ki_d"]
    assert "in command units" in text["u3"] and "K_T3 F3 = u3" in text["u3"]
    assert unit["Lambda_v1"] != "N.s/m" and unit["u1"] != "N"


@pytest.mark.parametrize("family", FAMILIES)
def test_no_description_repeats_a_word(descriptions, family):
    """No "platform platform displacement" anywhere, in any FMU."""
    for model in FMU_NAMES:
        for v in descriptions[family][model].modelVariables:
            assert not re.search(r"\b([A-Za-z]+) \1\b", v.description or ""), (model, v.name, v.description)


def test_sample_period_describes_the_rule(descriptions):
    for family in FAMILIES:
        (T_s,) = [v for v in descriptions[family][CONTROLLER].modelVariables if v.name == "T_s"]
        assert (T_s.unit, T_s.variability, T_s.start) == ("s", "fixed", "0.0001")
        for phrase in ("grid t0 + k T_s", "within 1e-4 T_s", "(k - k_prev) T_s, never the host's step",
                       "one logged warning"):
            assert phrase in T_s.description, phrase
