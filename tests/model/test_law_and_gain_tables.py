"""The law records (tapmp.laws) and the gains table (tapmp.settings) are what every list of laws
and gains reads: the C model's constants, the controller's settings, the scenario's laws, the
figures' labels, the study's tunable gains and the plausibility ranges."""

import pytest

from tapmp import cmodel, laws, settings
from tapmp.control import Gains, ModalGains
from tapmp.interface import CONTROLLER, RANGES, VARIABLES, allowed_text
from tapmp.params import GAIN_NAMES, GAIN_PRESETS, MODAL_GAIN_NAMES


def _var(name):
    return next(v for v in VARIABLES[CONTROLLER] if v.name == name)


def test_each_law_record_names_the_c_models_constant_of_its_id():
    _, lib = cmodel.load()
    assert [law.c_id for law in laws.LAWS] == list(range(len(laws.LAWS)))  # the law setting's range has no gap
    for law in laws.LAWS:
        assert getattr(lib, law.c_name) == law.c_id, law.name


def test_the_law_setting_allows_exactly_the_recorded_laws_and_names_them():
    v = _var("law")
    assert (v.min, v.max) == (0, len(laws.LAWS) - 1) == RANGES["law"]
    assert allowed_text(v) == "0 (SC-DC), 1 (APD-DC) or 2 (PID-DC)"
    assert v.description == "control law: 0 = SC-DC (Eq. 25), 1 = APD-DC (Eq. 38), 2 = PID-DC (modal PID on e)"
    assert laws.controller_description() == (
        "SC-DC synchronization controller with dynamics compensation (law 0), the APD-DC baseline (law 1) and "
        "the modal PID-DC baseline (law 2) for the TAPMP; outputs force commands F = u / K_T")


def test_the_tool_reads_the_laws_from_their_records():
    from orchestrator.studies.study_file import _TUNABLE
    from orchestrator.tool import plots, scenario
    from tapmp import modal

    assert scenario.LAWS == {"sc-dc": 0, "apd-dc": 1, "pid-dc": 2}
    assert [plots.label("x", law.name) for law in laws.LAWS] == ["SC-DC (proposed)", "APD-DC", "PID-DC"]
    # the laws' records give the Gains-tuned laws; pid-dc-full (PID-DC, one integral gain) is tuned on its modal gains
    assert _TUNABLE == {"sc-dc": ("Lambda_p", "Lambda_v", "b", "D"), "apd-dc": ("Lambda_p", "Lambda_v"),
                        "pid-dc-full": ("kp_c", "kp_d", "kv_c", "kv_d", "ki")}
    assert modal.LAWS == ("sc-dc", "apd-dc")  # the laws written as PID matrices of the per-motor gains
    with pytest.raises(ValueError, match="law = 'pid-dc' is invalid: allowed are sc-dc, apd-dc"):
        modal.law_matrices(Gains.from_preset(GAIN_PRESETS["default"]), "pid-dc")


def test_every_gain_a_law_reads_is_a_row_of_the_gains_table():
    for law in laws.LAWS:
        for _, name in law.gains:
            assert name in settings.SETTING, (law.name, name)


def test_the_gain_names_fields_units_and_ranges_come_from_the_gains_table():
    assert GAIN_NAMES == Gains._fields == ("Lambda_p", "Lambda_v", "b", "D", "K_T")
    assert MODAL_GAIN_NAMES == ModalGains._fields == ("kp_c", "kv_c", "ki_c", "kp_d", "kv_d", "ki_d")
    for preset in GAIN_PRESETS.values():
        assert tuple(preset) == GAIN_NAMES
    for row in settings.GAINS:
        names = [f"{row.name}{i}" for i in (1, 2, 3)] if row.per_motor else [row.name]
        for i, name in enumerate(names, start=1):
            v = _var(name)
            assert (v.unit, (v.min, v.max)) == (row.unit, row.range), name
            assert v.description == row.description.format(i=i), name
    assert _var("Lambda_v2").description.startswith("SC-DC Lambda_v on n (Eq. 25), APD-DC k_v on de (Eq. 38) of motor 2")


def test_a_swept_gains_axis_label_is_its_rows_label_and_unit():
    from orchestrator.studies.study_plots import key_label

    assert key_label("gain_overrides.D") == "D, error-filter gain (all motors) [1/s]"
    assert key_label("gain_overrides.Lambda_v2") == "Λv, velocity gain (motor 2) [s/m]"


def test_the_plausibility_ranges_are_the_tables_usual_ranges_in_the_variables_units():
    from orchestrator.tool.plausibility import USUAL

    assert set(name for _, name in USUAL) == set(settings.USUAL)
    for (section, name), (lo, hi, unit) in USUAL.items():
        assert (lo, hi) == settings.USUAL[name]
    assert USUAL[("plant", "c_v1")][2] == "N s/m" and USUAL[("plant", "I_y")][2] == "kg m^2"
