"""The co-simulation engine: FMU builds, SSP systems, the master loop and its clocks."""
