"""Experiments and their outputs: scenarios, runs, results, metrics, reports, figures, the stability pre-check."""
