"""The C text generated from the settings table (tapmp.interface.Var rows of every record in
tapmp.models): tapmp_settings.h, the range check of each model's settings struct, and each FMU's
reading of its parameters into that struct. Below the C model (tapmp.cmodel), which compiles the
header; it reads the records only, so no model's module is imported to generate it.
"""

from .models import MODELS, record


def allowed_text(v) -> str:
    """What a parameter's range rule allows, as its refusal says: "a number in [0, 1e+09]", "an
    integer in [1, 10000]" or the named values of an enumeration."""
    if v.type == "Integer":
        return v.choices or f"an integer in [{int(v.min)}, {int(v.max)}]"
    return f"a number in [{v.min:g}, {v.max:g}]"


def _c_double(x: float) -> str:
    return repr(float(x))


def _c_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def settings_check_source() -> str:
    """tapmp_settings.h: the C model's range check of each model's settings struct, one line per
    parameter in the order of its FMU variables (every value outside [min, max] refused with
    allowed_text), then the relations between settings (trajectory_domain_check)."""
    lines = ["/* Generated from the settings table (tapmp/interface.py, settings_check_source): do not edit.",
             " * Included at the end of tapmp_model.c, after offender() and the relation checks. */"]
    # plant first: the header's order since it was written (its bytes enter every FMU's instantiation token)
    for r in reversed([r for r in MODELS if r.settings_struct and not r.variant_of]):
        struct, table = r.settings_struct, r.variables
        lines += ["", f"int {struct}_check(const {struct} *s, const char **name, double *value, const char **allowed)",
                  "{"]
        for v in table:
            if v.causality != "parameter":
                continue
            x, kind = f"s->{v.field}", 2 if v.type == "Integer" else 1
            lines.append(f"    if (!({x} >= {_c_double(v.min)} && {x} <= {_c_double(v.max)}))")
            lines.append(f"        return offender({_c_string(v.name)}, {x}, {_c_string(allowed_text(v))}, {kind}, "
                         "name, value, allowed);")
        lines.append(f"    return {r.settings_relations}(s, name, value, allowed);" if r.settings_relations
                     else "    return 0;")
        lines.append("}")
    return "\n".join(lines) + "\n"


def settings_read_macro(model: str) -> str:
    """The C macro MODEL_READ_SETTINGS(inst, s) of ``model``'s model_vars.h: every parameter's
    value in the FMU instance ``inst`` (reals or ints, by value reference VR_<name>) into its
    member of the settings struct ``*s`` (the record's settings_struct); "" for a model without one."""
    if not record(model).settings_struct:
        return ""
    lines = [f"/* The parameters into the {record(model).settings_struct} *s (tapmp/interface.py: Var.field) */",
             "#define MODEL_READ_SETTINGS(inst, s) do { \\"]
    for v in record(model).variables:
        if v.causality == "parameter":
            values = "ints" if v.type == "Integer" else "reals"
            lines.append(f"    (s)->{v.field} = (inst)->{values}[VR_{v.name}]; \\")
    lines.append("} while (0)")
    return "\n".join(lines) + "\n"
