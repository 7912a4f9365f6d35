"""The search engine, below the history, the reports, the experiments and the plugin:
``requirements`` (the requirement language), ``tolerance`` (what a search's tolerance means),
``search`` (where runs go, when to stop, the
verdict), ``execution`` (trials and runs: perturb, run, score, cache) and ``outcomes`` (the
result types, their words and their stored form)."""

__all__: list[str] = []
