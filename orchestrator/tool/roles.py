"""The TAPMP system's roles: how scenarios and recorded columns name its elements.

A role (``plant``, ``controller``, ``trajectory``) addresses the one element of an SSP whose FMU
is TAPMP_Plant, TAPMP_Controller, TAPMP_Trajectory, whatever the SSP calls it; the master
(orchestrator.engine.master.CoSimulation, ``roles``) also writes that element's columns by the
role name, so the TAPMP system records the same columns under any element names.
"""

from tapmp.models import base_models

# Role names (the scenario's tables, the recorded columns) -> the modelName of the FMU they address:
# each model record's element (tapmp.models), as registered when the tool is imported.
ROLES = {r.element: r.name for r in base_models()}
# A scenario's own tables besides the roles: a misspelled one reaches the master as an element
# table, so these are among the names offered when a table addresses no element.
SCENARIO_TABLES = ("gain_overrides", "limits", "mismatch")
