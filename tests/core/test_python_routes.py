"""Every identification route from Python in a few lines: the snippets of docs/python.md, run as written.

The page holds one ``python`` block per route, written as a doctest (``>>>`` lines and the output they
print). Each block runs here in a namespace of its own, as a reader would paste it, and must print what
the page says; then the result it leaves behind is checked for what the snippet claims to have done.
"""

from __future__ import annotations

import doctest
import re
from pathlib import Path

import pytest

DOC = Path(__file__).resolve().parents[2] / "docs" / "python.md"
BLOCK = re.compile(r"^```python\n(.*?)^```", re.MULTILINE | re.DOTALL)
HEADING = re.compile(r"^## (.+)$", re.MULTILINE)
FLAGS = doctest.NORMALIZE_WHITESPACE | doctest.ELLIPSIS

#: The routes the page must show, by the start of their heading: the call that runs the route, and the
#: variable the block leaves holding its result, with that result's type.
ROUTES = {
    "Simulate": ("simulate(", "run", "SimulationResult"),
    "Least squares": ("identify_lse(", "res", "LSEResult"),
    "Transfer function": ("run_frequency_identification(", "fi", "FrequencyIdentification"),
    "Back-out": ("backout(", "b", "BackoutResult"),
    "Grey box": ("identify_greybox(", "gb", "GreyBoxResult"),
    "A study over seeds": ("run_study(", "study", "StudyResult"),
    "Black-box models": ("select_structure(", "table", "SelectionTable"),
}


def _blocks() -> list[tuple[str, int, str]]:
    """``(heading, line, code)`` of every python block of the page, in order."""
    text = DOC.read_text(encoding="utf-8")
    found = []
    for match in BLOCK.finditer(text):
        heading = HEADING.findall(text[:match.start()])[-1]
        found.append((heading, text.count("\n", 0, match.start()) + 2, match.group(1)))
    return found


BLOCKS = _blocks()


def _run(heading: str, line: int, code: str) -> dict:
    """Run one block as a doctest; fail with doctest's report of every difference. Returns its namespace."""
    test = doctest.DocTestParser().get_doctest(code, {}, f"docs/python.md: {heading}", str(DOC), line - 1)
    report: list[str] = []
    runner = doctest.DocTestRunner(optionflags=FLAGS)
    runner.run(test, out=report.append, clear_globs=False)
    assert test.examples, f"{heading}: the block has no >>> example"
    assert runner.failures == 0, "".join(report)
    return test.globs


def _route(heading: str):
    return next((v for k, v in ROUTES.items() if heading.startswith(k)), None)


def test_the_page_shows_every_route():
    headings = [h for h, _, _ in BLOCKS]
    for start, (call, _, _) in ROUTES.items():
        codes = [code for h, _, code in BLOCKS if h.startswith(start)]
        assert codes, f"docs/python.md has no block under a heading '{start}...' (headings: {headings})"
        assert any(call in code for code in codes), f"the '{start}' block never calls {call}"


@pytest.mark.parametrize("heading, line, code", [b for b in BLOCKS if not b[0].startswith("Figures")],
                         ids=[f"{h} (line {n})" for h, n, _ in BLOCKS if not h.startswith("Figures")])
def test_the_snippet_runs_as_written(heading, line, code):
    names = _run(heading, line, code)
    route = _route(heading)
    if route is None or route[1] not in names:
        return            # a second block of a route (tfest alone) checks itself with its own >>> lines
    _, variable, type_name = route
    result = names[variable]
    assert type(result).__name__ == type_name
    assert len(repr(result)) < 1000 and repr(result) == str(result)
    success = getattr(result, "success", getattr(result, "n_successful", 1) > 0)
    assert success, repr(result)


def test_the_figures_snippet_draws():
    matplotlib = pytest.importorskip("matplotlib")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    try:
        for heading, line, code in BLOCKS:
            if heading.startswith("Figures"):
                names = _run(heading, line, code)
                assert isinstance(names["fig"], matplotlib.figure.Figure)
    finally:
        plt.close("all")
