"""Scripts that reproduce rows of docs/compatibility.md (run as typed from the repository root)."""
