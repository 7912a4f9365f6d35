"""Pure algorithms below the engine: trajectory accuracy (ATE, RPE, scale), KITTI's t_rel and
r_rel, feature-tracking diagnostics, SuperPoint, and the trajectory plots. Nothing here imports
the plugin, the search or the storage; import the module you need (this package loads nothing)."""

__all__: list[str] = []
