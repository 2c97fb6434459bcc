"""FMI plumbing shared by the TAPMP FMUs (bundled into each FMU next to ``tapmp``)."""
