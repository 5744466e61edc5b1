"""File-based entry point: `panel serve eha_app/eha.py` (or `eha serve`).

Bokeh runs this file once per browser session, as a script of its own (named
``bokeh_app_...``), so every student gets a fresh app and state. Imported as a
module (``eha_app.eha``) it does nothing: no module of the app runs code on
import. The page's address carries what the student typed (see
:mod:`eha_app.runtime.connection`): a reload or a shared link restores it.
"""

from eha_app.app import serve_session

if __name__.startswith("bokeh_app_"):
    serve_session()
