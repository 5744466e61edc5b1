"""File-based entry point: `panel serve eha_app/eha.py` (or `eha serve`).

Bokeh runs this file once per browser session, so every student gets a fresh
app and state. The page's address carries what the student typed (see
:mod:`eha_app.connection`): a reload or a shared link restores it.
"""

import logging

import panel as pn

from eha_app.app import create_app, warm_up
from eha_app.serving import quiet_closed_websockets, use_local_resources

if not logging.getLogger("eha_app").handlers:
    # the app's notices (a closed page's cancelled runs, failures) in the server's log
    handler = logging.StreamHandler()
    handler.setFormatter(logging.Formatter("%(asctime)s %(message)s"))
    logging.getLogger("eha_app").addHandler(handler)
    logging.getLogger("eha_app").setLevel(logging.INFO)
warm_up()
quiet_closed_websockets()
use_local_resources(pn.state.curdoc)
# Neither the browser's details (language, time zone, ...) nor Panel's URL
# model are used: without them a page sends the server 8 fewer messages when
# it opens (the address is kept by eha_app.connection instead).
pn.config.browser_info = False

query = {k: v[-1].decode("utf-8", "replace") for k, v in (pn.state.session_args or {}).items() if v}
create_app(query=query).servable(title="EHA: modeling and identification", location=False)
