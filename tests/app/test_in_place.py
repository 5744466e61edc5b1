"""A result shown again changes the data of the models already on the page: no new Bokeh models
(none to make, serialise, send and lay out again), whatever the run (issue: every run of grey-box
built a new figure)."""

import panel as pn
import pytest
from bokeh.document import Document
from panel.io.state import set_curdoc

from eha_app.app import create_app


def _frequency(sec):
    sec.figure_tabs.active = 1              # Fig. 9, the closed-loop record: drawn when on show
    sec.run()


RUNS = {"simulation": lambda sec: sec.run("nonlinear"), "least_squares": lambda sec: sec.run(),
        "frequency": _frequency, "greybox": lambda sec: sec.run()}


@pytest.fixture(scope="module")
def served():
    doc = Document()
    with set_curdoc(doc):
        page = create_app()
        doc.add_root(pn.panel(page).get_root(doc))
        yield doc, page


def model_ids(doc) -> set[str]:
    doc.models.recompute()
    return {m.id for m in doc.models}


def plotted(doc) -> str:
    """Every curve on the page (the data sources' columns)."""
    import hashlib

    import numpy as np
    from bokeh.models import ColumnDataSource

    digest = hashlib.sha256()
    for m in sorted(doc.models, key=lambda m: m.id):
        if isinstance(m, ColumnDataSource):
            for name in sorted(m.data):
                digest.update(np.asarray(m.data[name]).tobytes())
    return digest.hexdigest()


@pytest.mark.parametrize("key", list(RUNS))
def test_a_second_run_makes_no_new_models(served, key):
    doc, page = served
    session = page.session
    page.show(key)
    section = session.build(key)
    RUNS[key](section)
    first = model_ids(doc)
    shown = plotted(doc)
    session.state.set_text("M", "7000")             # another plant: every curve and table changes
    try:
        RUNS[key](section)
        assert plotted(doc) != shown                # new curves were shown...
        assert model_ids(doc) - first == set()      # ...in the models already there
    finally:
        session.state.set_text("M", "6000")
