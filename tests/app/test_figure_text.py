"""The figures' text alternatives follow their data; lines are told apart by more than colour."""

from __future__ import annotations

import re

import numpy as np
from bokeh.models import Plot
from bokeh.palettes import Colorblind8

from eha_app.render import board_plots, plots
from eha_app.render.figure_text import describe_figure
from eha_app.session import Session
from eha_app.session.state import AppState


def _label(fig: Plot) -> str:
    assert fig.html_attributes["role"] == "figure"
    return fig.html_attributes["aria-label"]


def _numbers(text: str) -> set[str]:
    return set(re.findall(r"-?\d+(?:\.\d+)?(?:e[+-]?\d+)?", text))


def test_a_figure_says_what_it_plots_and_follows_each_update():
    tab = Session(AppState()).build("simulation")       # opens on the paper's Fig. 2: four runs
    figs = tab.grid.described_figures()
    assert len(figs) == 4 and all(isinstance(f, Plot) for f in figs)
    first = _label(figs[0])
    assert first.startswith("Figure. x [mm] against t [s].")
    x_mm = np.concatenate([np.asarray(a, dtype=float) for a in tab.grid.source.data["x"]])
    assert {f"{x_mm.min():.4g}", f"{x_mm.max():.4g}"} <= _numbers(first), first
    assert first.count("(nonlinear):") == 4
    # new data, new text: case 3 alone, both models
    tab._apply_preset(3)
    assert tab.run("both").state == "done"
    second = _label(figs[0])
    assert second != first and "(linear):" in second and "(nonlinear):" in second
    x_mm = np.concatenate([np.asarray(a, dtype=float) for a in tab.grid.source.data["x"]])
    assert f"{x_mm.max():.4g}" in _numbers(second)


def test_an_empty_figure_says_so_and_lists_few_points_one_by_one():
    bode = plots.BodeFigure()
    assert _label(bode.mag) == "Figure: Bode diagram. magnitude [dB] against ω [rad/s]. Nothing drawn yet."
    assert _label(bode.phase).startswith("Figure: Bode diagram, phase.")
    pz = board_plots.PoleZeroFigure()
    pz.poles.data = {"x": [-44.5, -385.0], "y": [0.0, 0.0], "color": ["#000"] * 2, "name": ["H1"] * 2,
                     "what": ["", ""], "flag": ["", ""]}
    assert "poles: 2 points at (-44.5, 0), (-385, 0)." in describe_figure(pz.fig)


def test_the_palettes_are_colour_blind_safe_and_dashes_tell_lines_apart():
    assert set(plots.CASE_COLORS) == {c.upper() for c in Colorblind8}
    colors = [c.upper() for c in Colorblind8]
    assert all(c in colors for c, _ in board_plots.BOARD_STYLES)
    styles = board_plots.BOARD_STYLES
    assert len(set(styles)) == len(styles) >= 14              # two references and twelve estimates
    assert all(a[0] != b[0] and a[1] != b[1] for a, b in zip(styles, styles[1:], strict=False))
    # runs of one model: each its dash; two models: the dash says the model
    tab = Session(AppState()).build("simulation")
    assert tab.grid.source.data["dash"] == ["solid", "dashed", "dotted", "dotdash"]
    tab._apply_preset(2)
    assert tab.run("both").state == "done"
    assert sorted(tab.grid.source.data["dash"]) == ["dashed", "solid"]
