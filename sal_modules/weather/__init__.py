"""Weather between scene and camera: fog, rain, snow."""
