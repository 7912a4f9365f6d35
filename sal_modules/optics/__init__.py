"""Lens and optics: soiling, cracks, defocus."""
