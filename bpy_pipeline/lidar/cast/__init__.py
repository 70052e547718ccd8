"""Casting: where the rays hit (the ray caster, Embree scenes, the compiled kernels, the scanner, visibility)."""
