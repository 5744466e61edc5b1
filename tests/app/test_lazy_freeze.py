"""A page update recomputes the document's model graph only when it changed the graph."""

from bokeh.document import Document
from bokeh.models import Column, ColumnDataSource, Div

from eha_app.runtime.tasks import lazy_freeze


def _counting(doc):
    calls = []
    original = doc.models.recompute

    def recompute():
        calls.append(1)
        original()
    doc.models.recompute = recompute
    return calls


def test_a_text_or_data_change_skips_the_walk_and_a_new_model_gets_it():
    doc = Document()
    col, src = Column(children=[Div(text="a")]), ColumnDataSource(data={"x": [1]})
    doc.add_root(col)
    doc.add_root(Column(children=[]))
    doc.roots[1].tags = [src.id]
    calls = _counting(doc)
    with lazy_freeze(doc):
        col.children[0].text = "b"
        src.data = {"x": [1, 2, 3]}
    assert calls == [] and col.children[0].text == "b"
    new = Div(text="new")
    with lazy_freeze(doc):
        col.children = [*col.children, new]
        col.children[0].text = "c"
    assert calls == [1] and doc.get_model_by_id(new.id) is new and new.document is doc
    # a removed model leaves the document
    with lazy_freeze(doc):
        col.children = col.children[:1]
    assert calls == [1, 1] and doc.get_model_by_id(new.id) is None
    # a new root, and nesting: the outer block decides
    with lazy_freeze(doc):
        with lazy_freeze(doc):
            doc.add_root(Div(text="root"))
    assert len(calls) == 3 and len(doc.roots) == 3
    assert "invalidate" not in vars(doc.models)                 # the document's own method is back
