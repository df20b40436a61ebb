"""Helmholtz coil driver: field<->current maths, supply wire dialects, coils node."""
