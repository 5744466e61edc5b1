"""File-based entry point: `panel serve eha_app/eha.py` (or `eha serve`).

Bokeh runs this file once per browser session, so every student gets a fresh
app and state.
"""

from eha_app.app import create_app, warm_up

warm_up()

create_app().servable(title="EHA: modeling and identification")
