"""Bokeh's stable property defaults, kept per class: the same models, the same JSON, themes still apply."""

import json
import os
import subprocess
import sys

SCRIPT = r"""
import json, re, sys
import panel as pn
from bokeh.document import Document
from bokeh.themes import Theme
from panel.io.state import set_curdoc
if sys.argv[1] == "cached":
    from eha_app.runtime.patches import cache_stable_defaults
    cache_stable_defaults()
    from bokeh.core.property.descriptors import PropertyDescriptor
    assert PropertyDescriptor._get_default._eha_cached
from eha_app.app import create_app
from eha_app.session import Session
from eha_app.session.state import AppState
doc = Document()
with set_curdoc(doc):
    page = create_app()
    doc.add_root(pn.panel(page).get_root(doc))
    for key in ("simulation", "least_squares", "frequency", "board"):
        page.show(key)
    text = re.sub(r"at 0x[0-9a-f]+", "at 0x", json.dumps(doc.to_json().content, default=str, sort_keys=True))
    # ids in the order they first appear (Bokeh's counter, Panel's uuids differ from run to run)
    ids = {}
    out = {"doc": re.sub(r"\bp\d{4,}\b|[0-9a-f]{32}|[0-9a-f]{8}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{12}",
                         lambda m: ids.setdefault(m.group(0), f"id{len(ids)}"), text)}
# a theme still overrides a default
from bokeh.plotting import figure
themed = Document()
themed.theme = Theme(json={"attrs": {"Title": {"text_font_size": "31px"}}})
f = figure(title="t")
themed.add_root(f)
out["themed"] = f.title.text_font_size
plain = figure(title="t")
out["plain"] = plain.title.text_font_size
print(json.dumps(out, default=str))
"""


def _run(mode):
    # one hash seed for both: a set's members serialise in its order
    env = {**os.environ, "PYTHONHASHSEED": "0"}
    done = subprocess.run([sys.executable, "-c", SCRIPT, mode], capture_output=True, text=True, timeout=300, env=env)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_a_page_serialises_the_same_with_the_defaults_kept():
    own, cached = _run("bokeh"), _run("cached")
    assert cached["themed"] == "31px" and cached["plain"] == own["plain"] != "31px"
    assert len(own["doc"]) > 100_000 and own["doc"] == cached["doc"]
