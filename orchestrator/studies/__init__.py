"""Studies on Dask: parameter sweeps, Monte-Carlo robustness, gain tuning."""
