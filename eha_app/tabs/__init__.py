"""The three tabs of the app, one Viewer class each (the paper's three steps)."""
