"""Where and how runs happen: ``trial_runner`` (one trial: its runs and the cache), ``run_job``
(one run as a self-contained job: perturb, run, score), ``executor`` / ``executor_factory`` /
``ray_executor`` (in process, in a local pool, as Ray tasks) and ``early_stop`` (when a run's
requirement can no longer hold)."""

__all__: list[str] = []
