"""The tool every user runs, for any controller: scenarios, runs, results, metrics, reports, figures,
export, the stability pre-check and analysis, and the compare workflow."""
