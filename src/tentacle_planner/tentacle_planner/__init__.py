"""Path handling, optimiser, scenes and schedule files, schedule player node."""
