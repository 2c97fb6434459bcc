"""The generic co-simulation engine: the SSP reader, the master loop, its schedule and clocks, the
compiled stepping core, Model Exchange and the loaded FMUs. It knows no TAPMP model: any FMI 2.0/3.0
Co-Simulation or Model Exchange FMUs in an SSP."""
