"""The server's changes to how Bokeh makes and serialises models (stable defaults kept per class, theme
values read from the instance, settings fixed, empty container defaults made only when read): the
same models, the same JSON, themes still apply."""

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
    from eha_app.runtime import patches
    patches.cache_stable_defaults()
    patches.fast_themed_values()
    patches.settle_settings()
    patches.lazy_container_defaults()
    import bokeh.model.util
    from bokeh.core.has_props import HasProps
    from bokeh.core.property.descriptors import PropertyDescriptor
    assert PropertyDescriptor._get_default._eha_cached and HasProps.themed_values._eha_fast
    assert bokeh.model.util.visit_immediate_value_references._eha_lazy
from eha_app.app import create_app
from eha_app.session import Session
from eha_app.session.state import AppState
doc = Document()
with set_curdoc(doc):
    page = create_app()
    doc.add_root(pn.panel(page).get_root(doc))
    for key in ("simulation", "least_squares", "frequency", "board"):
        page.show(key)
    first = doc.to_json().content
    # serialised again (a server serialises a model at every change): what the first pass read
    # must not change the second
    text = re.sub(r"at 0x[0-9a-f]+", "at 0x", json.dumps([first, doc.to_json().content], default=str,
                                                          sort_keys=True))
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


GC_SCRIPT = r"""
import gc, json, weakref
import panel.io.document as panel_document
from eha_app.runtime.patches import tune_garbage_collector
tune_garbage_collector()
out = {"frozen": gc.get_freeze_count()}
class Node:
    pass
# a cycle alive through a full collection is frozen with the survivors ...
a, b = Node(), Node()
a.other, b.other = b, a
alive = weakref.ref(a)
frozen = gc.get_freeze_count()
gc.collect()
out["frozen_more"] = gc.get_freeze_count() > frozen
# ... so an ordinary collection no longer finds it once it is garbage (a closed page's objects) ...
del a, b
gc.collect()
out["kept_while_frozen"] = alive() is not None
# ... the collection after a discarded session does, and freezes the survivors again
panel_document._panel_last_cleanup = -1e9
panel_document._garbage_collect()
out["collected"] = alive() is None
out["refrozen"] = gc.get_freeze_count() > 1_000
print(json.dumps(out))
"""


def test_the_server_freezes_what_outlives_a_full_collection_and_collects_it_when_a_page_closes():
    done = subprocess.run([sys.executable, "-c", GC_SCRIPT], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    out = json.loads(done.stdout.strip().splitlines()[-1])
    assert out["frozen"] > 1_000           # what was loaded at start, never scanned again
    assert out["frozen_more"] and out["kept_while_frozen"] and out["collected"] and out["refrozen"]
