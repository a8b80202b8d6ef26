"""The run's bookkeeping, between the studies and the workflow.

The config parsed once into typed objects (:mod:`run.config`), the jobs' logs
(:mod:`run.joblog`), the working directory's run lock (:mod:`run.workdir`) and the run's log of
job times (:mod:`run.run_log`).
"""
