"""The FMU builder: TAPMP's models (tapmp) packaged as FMUs (pythonfmu and native FMI 2.0/3.0),
their modelDescription, documentation and icons, the container FMU, the FMU families and the SSP
writer. Between the model and the tool; the generic master (orchestrator.engine) knows nothing of it."""
