"""Numerical core of the EHA teaching tool: model, simulation, identification.

Importing this package stays light: it never imports panel, holoviews or bokeh,
and python-control / numba are imported only when a function needs them.
"""
