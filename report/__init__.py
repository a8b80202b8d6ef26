"""The workflow's report: one HTML page built from the studies' typed results."""
