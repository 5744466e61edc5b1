"""Panel web app on top of :mod:`eha_core`."""

#: The project's version, read by pyproject.toml (the one place it is written) and by ``eha --version``
#: when the distribution is not installed.
__version__ = "0.1.0"
