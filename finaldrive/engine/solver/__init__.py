"""Numerics: augmented Lagrangian, integrators, static equilibrium."""
