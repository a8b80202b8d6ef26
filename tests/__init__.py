"""The test suite, in layers (markers in pyproject.toml): unit, solve, workflow, cluster."""
