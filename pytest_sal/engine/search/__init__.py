"""Where a requirement's runs go and when its search stops: ``requirement_search`` (a
requirement -> ``Outcome``, the entry of both front ends), ``bisection`` (a deterministic
system's bracket), ``reliability_curve`` / ``reliability_search`` / ``reliability_outcome`` (a
noisy system's fitted pass probability, where its next runs go, its verdict) and
``reliability_compare`` (the statistical gate's tests)."""

__all__: list[str] = []
