"""Helmholtz coil driver: field-to-current maths, supply wire dialects, coils node."""
