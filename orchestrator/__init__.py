"""fmpy-based master algorithm, scenarios, results and reports for the TAPMP FMUs."""
