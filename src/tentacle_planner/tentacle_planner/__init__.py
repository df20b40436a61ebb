"""Tentacle statics model, optimiser, schedule files and schedule player."""
