# The serve entry point builds an app when imported: not a module for doctests.
collect_ignore = ["eha_app/eha.py"]
