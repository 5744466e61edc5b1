"""Panel 2.0 readiness: no deprecation warning comes from the project's own code.

The suite's ``filterwarnings`` (pyproject.toml) make a DeprecationWarning or
PendingDeprecationWarning attributed to a module of eha_app or eha_core an error. A warnings
filter's module is the module the warning is attributed to (the caller at the warning's
stacklevel): a library that attributes its deprecation to its own frames escapes it. So the
whole page, every tab, is also built here with every warning recorded with its stack: a
deprecation with a frame of the project on its stack is the project's to fix, wherever it was
attributed.
"""

from __future__ import annotations

import os
import traceback
import warnings
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import panel as pn
import pytest
from _pytest.config import apply_warning_filters
from bokeh.document import Document
from panel.io.state import set_curdoc

import eha_app
import eha_core
from eha_app.app import create_app
from eha_app.dashboard import Dashboard
from eha_app.runtime.handins import HandIns
from eha_app.session.state import AppState
from eha_core.exercise import Exercise

PROJECT_DIRS = tuple(str(Path(m.__file__).resolve().parent) + os.sep for m in (eha_app, eha_core))
DEPRECATIONS = (DeprecationWarning, PendingDeprecationWarning, FutureWarning)
FREQUENCY = str(Path(eha_app.__file__).resolve().parent / "sections" / "frequency.py")


def _in_project(filename: str) -> bool:
    return os.path.realpath(filename).startswith(PROJECT_DIRS)


@contextmanager
def configured_filters(config):
    """The warnings filters of pyproject.toml alone, over "always" (what ``-W always::...`` on the
    command line would otherwise override)."""
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        apply_warning_filters(config.getini("filterwarnings"), [])
        yield


@pytest.mark.parametrize("category", [DeprecationWarning, PendingDeprecationWarning])
@pytest.mark.parametrize("module", ["eha_app.sections.frequency", "eha_core.study"])
def test_the_configured_filters_make_a_deprecation_from_project_code_an_error(request, category, module):
    with configured_filters(request.config):
        with pytest.raises(category, match="^x$"):
            warnings.warn_explicit("x", category, FREQUENCY, 1, module=module)
        # a library's own deprecation (attributed to its frames) is not the project's to fix here
        with pytest.warns(category, match="^x$"):
            warnings.warn_explicit("x", category, "elsewhere.py", 1, module="some_library.widgets")


@pytest.mark.parametrize("call, message", [
    ("pn.widgets.Select(name='βe from', options=['a'])", "Widget.name is deprecated"),
    ("pn.widgets.Button(label='Go', button_type='primary')", "button_type is deprecated"),
])
def test_a_deprecated_panel_call_made_from_project_code_is_an_error(request, call, message):
    """Panel attributes these to its caller: code run as a module of eha_app fails."""
    code = compile(call, FREQUENCY, "exec")
    with configured_filters(request.config):
        with pytest.raises(PendingDeprecationWarning, match=message):
            exec(code, {"__name__": "eha_app.sections.frequency", "__file__": FREQUENCY, "pn": pn})
        with pytest.warns(PendingDeprecationWarning, match=message):       # the same call elsewhere
            exec(code, {"__name__": "some_library.widgets", "pn": pn})


@dataclass
class Recorded:
    category: type
    message: str
    filename: str
    lineno: int
    stack: list

    def project_frame(self):
        """The innermost frame of eha_app or eha_core on the warning's stack, or None."""
        return next((f for f in reversed(self.stack) if _in_project(f.filename)), None)

    def __str__(self):
        f = self.project_frame()
        where = f"{f.filename}:{f.lineno} ({f.line})" if f is not None else "no project frame"
        return f"{self.category.__name__}: {self.message} [attributed to {self.filename}:{self.lineno}; from {where}]"


@contextmanager
def recording():
    """Every warning of the block, each with the stack that issued it (no filter ignores one)."""
    seen: list[Recorded] = []

    def hook(message, category, filename, lineno, file=None, line=None):
        seen.append(Recorded(category, str(message), filename, lineno, traceback.extract_stack()[:-1]))

    with warnings.catch_warnings():
        warnings.simplefilter("always")
        warnings.showwarning = hook
        yield seen


def project_deprecations(seen: list[Recorded]) -> list[Recorded]:
    return [w for w in seen if issubclass(w.category, DEPRECATIONS)
            and (_in_project(w.filename) or w.project_frame() is not None)]


def build_everything(page) -> None:
    """The page's bokeh models, then every tab and section (as a student opens them)."""
    doc = Document()
    with set_curdoc(doc):
        doc.add_root(pn.panel(page).get_root(doc))
        for placement in page.session.registry:
            page.show(placement.key)


def test_the_recorder_sees_a_deprecation_made_from_project_code():
    """The check below can fail: a deprecated call on a project frame's stack is found, even when
    the library attributes the warning to itself (stacklevel=1)."""
    code = compile("warnings.warn('old API', PendingDeprecationWarning, stacklevel=1)", FREQUENCY, "exec")
    with recording() as seen:
        exec(code, {"__name__": "eha_app.sections.frequency", "warnings": warnings})
        warnings.warn_explicit("inside a library", DeprecationWarning, "lib.py", 1, module="lib")
    found = project_deprecations(seen)
    assert [w.message for w in found] == ["old API"] and found[0].project_frame().filename == FREQUENCY


def test_the_whole_page_and_every_tab_are_built_without_a_deprecation():
    with recording() as seen:
        page = create_app(AppState())
        build_everything(page)
    assert page.session.section("frequency") is not None and len(page.tabs.built) == len(page.tabs.names)
    found = project_deprecations(seen)
    if found:
        pytest.fail("deprecated calls of the project:\n" + "\n".join(map(str, found)), pytrace=False)


def test_an_exercise_page_and_the_dashboard_are_built_without_a_deprecation(tmp_path, monkeypatch):
    ex = Exercise.new(hide=("M", "B", "Af", "beta_e"), vary=0.25, title="Lab 3", secret="5a" * 32,
                      roster=[("s1", "Ada Lovelace")])
    path = tmp_path / "class.json"
    ex.save(path)
    monkeypatch.setenv("EHA_EXERCISE", str(path))
    with recording() as seen:
        page = create_app(AppState())
        page.gate.student_id.value = ex.join_code("s1")
        page.gate.start()
        assert page.session.student == "s1"
        build_everything(page)
        dash = Dashboard(ex, HandIns(path).check())
        doc = Document()
        with set_curdoc(doc):
            doc.add_root(pn.panel(dash).get_root(doc))
    found = project_deprecations(seen)
    if found:
        pytest.fail("deprecated calls of the project:\n" + "\n".join(map(str, found)), pytrace=False)
