"""The defaults of `tapmp frf` (orchestrator.tool.frf), apart from it so that the command's parser
reads them without importing numpy, fmpy or the master."""

PERIOD = 0.2        # period of the multisine [s]: its frequency resolution is 1 / PERIOD
TRANSIENT = 2       # periods run before the measurement (the loop settles into its periodic state)
PERIODS = 4         # periods measured and averaged
POINTS = 40         # excited frequencies per direction
AMPLITUDE = 10.0    # RMS of the injected force per direction [N]
LINEAR_SHARE = 0.5  # the run counts as linear if max |u| stays below this share of the force limit
