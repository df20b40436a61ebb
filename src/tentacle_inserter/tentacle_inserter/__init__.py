"""Linear insertion axis: stage wire dialects and inserter node."""
