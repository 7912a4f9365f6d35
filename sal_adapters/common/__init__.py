"""What every package of pytest-sal shares, below the datasets: the error classes of the
adapters (``errors``), name -> object registries fed by entry points (``plugins``), lazy package
namespaces (``lazy``), whole-or-nothing outputs (``atomic``), lock files (``file_lock``), text
tables and YAML read within stated limits (``textfiles``, ``bounded_yaml``), short quoting of
values in messages (``quoting``), did-you-mean hints (``suggest``), values as plain JSON
(``json_values``), calls that differ across library versions (``compat``) and the user cache
folder (``cache_dir``). Nothing here imports numpy at package import."""

__all__: list[str] = []
