"""File-based entry point of the teacher's dashboard, served at /teacher beside the app (``eha serve
--exercise``); only the teacher's cookie reaches it (:mod:`eha_app.runtime.teacher_access`).

Bokeh runs this file once per browser session; imported as a module it does nothing.
"""

from eha_app.dashboard import serve_dashboard

if __name__.startswith("bokeh_app_"):
    serve_dashboard()
