"""Panel web app on top of :mod:`eha_core`."""
