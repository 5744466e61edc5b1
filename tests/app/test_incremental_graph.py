"""The server finds a page's models from what changed (``incremental_graph`` in
eha_app/runtime/patches.py): after every step of a student's path, the models it attached, their
names and what it detached are those of Bokeh's own walk over the whole page."""

import os
import subprocess
import sys

SCRIPT = r"""
import json, os, sys, tempfile
from pathlib import Path
import panel as pn
from bokeh.document import Document
from bokeh.document.models import DocumentModelManager
from eha_app.runtime import patches
from eha_core.exercise import Exercise

bokehs_own = DocumentModelManager.recompute
assert patches.apply_patches(["lazy_containers", "incremental_graph"]) == {
    "lazy_containers": "applied", "incremental_graph": "applied"}
assert DocumentModelManager.recompute._eha_incremental

tmp = Path(tempfile.mkdtemp())
ex = Exercise.new(hide=("M", "B", "Af", "beta_e"), roster=[("s1", "Ada")])
ex.save(tmp / "class.json")
os.environ["EHA_EXERCISE"] = str(tmp / "class.json")
from eha_app.app import create_app
from eha_app.session.state import AppState

def walked(doc):
    # Bokeh's own walk, on a copy of the manager's state: what it would attach now
    found = set()
    for root in doc.roots:
        found |= root.references()
    return found

problems, steps = [], []
def check(doc, step):
    kept = set(doc.models)
    truth = walked(doc)
    steps.append((step, len(kept)))
    if {m.id for m in kept} != {m.id for m in truth}:
        problems.append(f"{step}: {len(kept - truth)} kept that Bokeh would drop, {len(truth - kept)} missing")
    if any(m.document is not doc for m in truth):
        problems.append(f"{step}: a model of the page is not attached to it")
    names = {n: sorted(m.id for m in truth if m.name == n) for n in {m.name for m in truth if m.name}}
    for n, ids in names.items():
        if sorted(m.id for m in doc.models.get_all_by_name(n)) != ids:
            problems.append(f"{step}: models named {n!r} differ")

doc = Document()
page = create_app(AppState())
doc.add_root(pn.panel(page).get_root(doc))
check(doc, "gate")
page.gate.student_id.value = ex.join_code("s1")
page.gate.start()
s = page.session
check(doc, "joined")
tabs = page.tabs
def frozen(fn):
    with patches.lazy_freeze(doc):
        fn()
for i, step in enumerate(("tab 1", "tab 2")):
    frozen(lambda i=i: tabs.build(tabs.names[i]))
    check(doc, step)
frozen(lambda: s.section("simulation").run("both")); check(doc, "compare")
frozen(lambda: tabs.build(tabs.names[2])); check(doc, "tab 3")
sub = tabs.built[tabs.names[2]].lazy
frozen(lambda: s.section("least_squares").run()); check(doc, "least squares")
for k, run in ((1, "frequency"), (2, "greybox")):
    frozen(lambda k=k: sub.build(sub.names[k])); check(doc, f"sub-tab {k}")
    frozen(lambda run=run: s.section(run).run()); check(doc, run)
frozen(lambda: sub.build(sub.names[3])); check(doc, "sub-tab 3, the black-box models")
frozen(lambda: s.section("blackbox").run()); check(doc, "blackbox")
frozen(lambda: sub.build(sub.names[4])); check(doc, "board")
board = s.section("board")
for view in ("bode", "step", "pz", "fit"):
    frozen(lambda view=view: board.show_view(view)); check(doc, f"board {view}")
frozen(lambda: board.delete(board.entries[-1])); check(doc, "board: a model deleted")
frozen(lambda: s.section("greybox").hand_in()); check(doc, "hand-in")
form = s.section("parameters").form
frozen(lambda: setattr(form, "values", {**form.values, "ps": "20"})); check(doc, "tab 1 typed again")
# unfrozen changes too (Bokeh recomputes at once)
s.section("least_squares").run(); check(doc, "least squares again, unfrozen")
print(json.dumps({"problems": problems, "steps": steps}))
"""


def test_the_models_found_from_what_changed_are_those_of_bokehs_walk(tmp_path):
    env = {**os.environ, "EHA_PATCHES_OFF": ""}
    done = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, env=env, timeout=600,
                          cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-4000:]
    import json

    out = json.loads(done.stdout.strip().splitlines()[-1])
    assert out["problems"] == []
    sizes = dict(out["steps"])
    # the path grew the page (else the comparison proved little), and deleting a model shrank it
    assert sizes["hand-in"] > sizes["joined"] + 300
    assert sizes["board: a model deleted"] < sizes["board fit"]
