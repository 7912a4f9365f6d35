"""What a search produces and how it reads: ``run_record`` (``RunRecord``: one run, from its score
to the report), ``trial`` (``Trial``, ``TrialMetrics``), ``outcome`` (``Boundary``, ``Outcome`` and
their words), ``quantity`` (the one number formatter), ``json_shape`` (stored JSON checked against
the dataclass it is read into) and ``legacy_units`` (old history in old units)."""

__all__: list[str] = []
