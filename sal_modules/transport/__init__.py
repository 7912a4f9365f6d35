"""Video transport: frame drops, compression, bandwidth limits."""
