"""The search engine: requirements, the boundary search, trials (perturb, run, score, judge) and
the outcome of a requirement. Below the history, the reports, the experiments and the plugin."""

__all__: list[str] = []
