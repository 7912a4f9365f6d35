"""Light and sensor: night, sensor noise, sun glare."""
