"""The study in the app: the same numbers as the core's, a cancel that keeps what was done, no study in an exercise."""

import numpy as np
import pytest

from eha_app.session import Session
from eha_app.session.state import AppState


def test_a_least_squares_study_shows_the_cores_figures():
    from eha_core.study import StudyConfig, run_study

    panel = Session(AppState()).build("study")
    panel.CHUNK_SEEDS = {"lse": 5, "tf": 2}        # three jobs: 5, 5 and 2 seeds, the queue's turns between
    panel.form.values = {**panel.form.values, "study_seeds": "12"}
    panel.run()
    assert [p.n_requested for p in panel._parts] == [5, 5, 2]
    res = panel.result
    direct = run_study(StudyConfig("lse", n_seeds=12, disturbance="white:1000"), workers=1)
    assert res.n_completed == 12 and not res.cancelled
    for name in res.parameters:
        np.testing.assert_allclose(res.values(name), direct.values(name), rtol=1e-12)
        assert res.coverage[name] == direct.coverage[name]
    assert panel.figure.names == res.parameters
    assert sum(panel.figure.sources["B"].data["top"]) == 12
    assert "covered" in panel.figure.figs[1].title.text and "12 of 12 seeds" in panel.status.object
    assert "95 % interval covered the truth" in panel.summary.object
    assert not panel.progress.visible and not panel.button.disabled and panel.cancel_button.disabled


def test_a_cancelled_study_keeps_the_seeds_done():
    panel = Session(AppState()).build("study")
    panel.CHUNK_SEEDS = {"lse": 10, "tf": 2}
    panel.form.values = {**panel.form.values, "study_seeds": "40"}
    calls = []
    original = panel._show_progress

    def progress(done, total):
        calls.append(done)
        original(done, total)
        if done >= 3:
            panel.cancel()

    panel._show_progress = progress
    panel.run()
    res = panel.result
    assert res.cancelled and 3 <= res.n_completed < 40
    assert "(cancelled)" in panel.status.object


def test_the_form_checks_and_switches_fields():
    panel = Session(AppState()).build("study")
    assert "study_noise" in panel.form.hidden and "study_white" not in panel.form.hidden
    panel.form.values = {**panel.form.values, "study_kind": "tf"}
    assert "study_white" in panel.form.hidden and "study_noise" not in panel.form.hidden
    panel.form.values = {**panel.form.values, "study_seeds": "5000"}
    assert panel.form.errors["study_seeds"].startswith("seeds N = 5000 is not allowed")
    assert panel.button.disabled


def test_no_study_in_an_exercise():
    state = AppState()
    state.secret = {"M": 4000.0}
    panel = Session(state).build("study")
    assert panel.button.disabled and panel.exercise_note.visible
    assert panel.run() is None


@pytest.mark.parametrize("model", ["linear"])
def test_a_transfer_function_study(model):
    panel = Session(AppState()).build("study")
    panel.form.values = {**panel.form.values, "study_kind": "tf", "study_seeds": "3", "study_model": model}
    panel.run()
    assert panel.result.parameters == ("a1", "a2", "a3", "b0") and panel.result.n_completed == 3


def test_one_study_at_a_time():
    panel = Session(AppState()).build("study")
    panel._running(True)                          # as while a study waits or runs
    panel.form.values = {**panel.form.values, "study_seeds": "30"}
    assert panel.button.disabled and not panel.cancel_button.disabled
    assert panel.run() is None
    panel._running(False)
    assert not panel.button.disabled


def test_a_study_ending_while_tab_1_is_invalid_leaves_its_button_disabled():
    """Found by the long random walk: a study that ended (or was cancelled) while a tab-1 field was
    invalid enabled "Run the study" again."""
    state = AppState()
    panel = Session(state).build("study")
    panel._running(True)
    state.set_text("pr", "1000")                   # above the supply pressure
    assert not state.valid
    panel._running(False)
    assert panel.button.disabled and panel.cancel_button.disabled
    state.set_text("pr", "0")
    assert state.valid and not panel.button.disabled


def test_the_study_speaks_the_apps_vocabulary_and_shows_bias_against_its_error():
    """β_e (not beta_e), numbers as 8.787·10⁸ (not 8.7873e+08), units in the table and axes, a legend
    for the histograms, and each bias against its standard error (spread / √seeds)."""
    import re

    panel = Session(AppState()).build("study")
    panel.form.values = {**panel.form.values, "study_seeds": "12"}
    panel.run()
    res, html = panel.result, panel.summary.object
    assert "beta_e" not in html and "β<sub>e</sub> [GPa]" in html and "M [kg]" in html and "B [N s/m]" in html
    assert not re.search(r"\d[eE][+-]\d", html)
    assert "·10<sup>9</sup>" not in html                   # βe in GPa, as tab 1 writes it
    assert "bias / its std error" in html and "Histograms:" in html and "nominal" in html and "mean" in html
    # the t statistic of the bias, from the core's figures
    n = res.values("M").size
    t = (res.mean["M"] - res.nominal["M"]) / (res.std["M"] / np.sqrt(n))
    assert f"{t:+.1f}" in html
    titles = [f.title.text for f in panel.figure.figs]
    assert titles[-1].startswith("βe:") and not any("beta_e" in t for t in titles)
    d0 = panel.figure.figs[res.parameters.index("d0")]
    assert d0.xaxis.axis_label == "estimate − nominal [N]"


def test_histograms_of_estimates_near_the_largest_float_are_drawn_not_refused():
    """An estimate of 1e308 against a nominal value of 1e-3 overflowed to inf and np.histogram refused the
    figure (a traceback in the server's log; found by the long random walk)."""
    import types
    import warnings

    from eha_app.sections.study import StudyFigure

    values = {"M": np.array([4000.0, 4100.0, 3900.0]), "B": np.array([1e308, -1e308, 1.0]),
              "beta_e": np.array([np.inf, 1.0, 2.0])}
    result = types.SimpleNamespace(values=lambda n: values[n], nominal={"M": 4000.0, "B": 1e-3, "beta_e": 1.5},
                                   coverage={"M": 1.0, "B": 0.0, "beta_e": 0.5})
    fig = StudyFigure(("M", "B", "beta_e"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")                 # no overflow warning reaches the log either
        fig.update(result)
    assert sum(fig.sources["M"].data["top"]) == 3 and sum(fig.sources["beta_e"].data["top"]) == 2
    assert sum(fig.sources["B"].data["top"]) == 1 and fig.figs[1].title.text.startswith("B: mean")


def test_a_grey_box_study_on_tab_1s_actuator_against_the_cramer_rao_bound():
    import dataclasses

    from eha_core.identify.greybox_study import GreyBoxStudyConfig
    from eha_core.study import StudyConfig, run_study

    session = Session(AppState())
    session.state.set_text("M", "5000")
    panel = session.build("study")
    panel.CHUNK_SEEDS = {**panel.CHUNK_SEEDS, "greybox": 2}       # two jobs: 2 and 2 seeds
    panel.form.values = {**panel.form.values, "study_kind": "greybox", "study_seeds": "4",
                         "study_gb_params": "M, βe", "study_gb_measured": "x, p2", "study_snr": "40"}
    assert {"study_white", "study_noise"} <= set(panel.form.hidden) and "study_snr" not in panel.form.hidden
    panel.run()
    res = panel.result
    assert [p.n_requested for p in panel._parts] == [2, 2] and res.n_completed == 4 and not res.cancelled
    assert res.parameters == ("M", "beta_e") and res.nominal["M"] == 5000.0          # tab 1's actuator
    # the same seeds as the core's study run at once
    cfg = StudyConfig("greybox", n_seeds=4, greybox=GreyBoxStudyConfig(params=("M", "beta_e"), measured=("x", "p2"),
                                                                       snr_db=40.0))
    direct = run_study(cfg, session.state.params, workers=1)
    for name in res.parameters:
        np.testing.assert_allclose(res.values(name), direct.values(name), rtol=1e-12)
    assert res.bound == direct.bound and all(b > 0 for b in res.bound.values())
    # the intervals counted are the estimator's own (log-scale for a positive parameter): asymmetric
    lo, hi = res.seeds[0].interval("M")
    assert hi - res.seeds[0].estimates["M"] > res.seeds[0].estimates["M"] - lo
    assert "Cramér-Rao bound" in panel.summary.object and "spread / bound" in panel.summary.object
    # the form refuses what the estimator would
    panel.form.values = {**panel.form.values, "study_gb_params": "M, Q"}
    assert "Q is not one of" in panel.form.errors["study_gb_params"] and panel.button.disabled
    assert dataclasses.replace(cfg, n_seeds=2).greybox is cfg.greybox


def test_a_studys_parts_compute_in_the_servers_child_process():
    import os

    from eha_app.runtime.background import background_process

    panel = Session(AppState()).build("study")
    panel.CHUNK_SEEDS = {**panel.CHUNK_SEEDS, "lse": 5}
    panel.form.values = {**panel.form.values, "study_seeds": "12"}
    child = background_process()
    calls = child.calls
    panel.run()
    assert panel.result.n_completed == 12 and [p.n_completed for p in panel._parts] == [5, 5, 2]
    assert child.calls - calls == 3 and child.pid not in (None, os.getpid())


def test_the_histograms_are_made_when_asked_for_and_fill_in_part_by_part():
    panel = Session(AppState()).build("study")
    panel.CHUNK_SEEDS = {**panel.CHUNK_SEEDS, "lse": 5}
    panel.form.values = {**panel.form.values, "study_seeds": "12"}
    shown = []
    original = panel._run_part

    def part(cfg, params, first):
        # before each part: the figure exists, holding the seeds done so far
        first_name = panel.figure.names[0]
        shown.append((panel.figure.names, sum(panel.figure.sources[first_name].data["top"])))
        return original(cfg, params, first)

    panel._run_part = part
    panel.run()
    names = ("M", "B", "Af", "d0", "beta_e")
    assert shown == [(names, 0), (names, 5), (names, 10)]
    assert sum(panel.figure.sources["M"].data["top"]) == 12 and panel.plot.objects == [panel.figure.layout]
    # another study of the same parameters keeps its figures; another kind makes its own
    figure = panel.figure
    panel.form.values = {**panel.form.values, "study_seeds": "3"}
    panel.run()
    assert panel.figure is figure
    shown.clear()
    panel.form.values = {**panel.form.values, "study_kind": "tf", "study_seeds": "2"}
    panel.run()
    assert shown == [(("a1", "a2", "a3", "b0"), 0)]
    assert panel.figure is not figure and panel.figure.names == ("a1", "a2", "a3", "b0")
    assert panel.result.parameters == panel.figure.names


def test_a_study_stopped_before_its_first_seeds_shows_the_earlier_one_again():
    panel = Session(AppState()).build("study")
    panel.form.values = {**panel.form.values, "study_seeds": "12"}
    panel.run()
    earlier = panel.result
    assert "95 % interval covered the truth" in panel.summary.object
    # the next study waits for its first part (queued), its page says what the histograms show
    panel._run_part = lambda cfg, params, first: None
    panel.run()
    assert "histograms show the seeds done so far" in panel.summary.object
    panel._cancelled(None)                      # cancelled before its first part ran
    assert panel.result is earlier and "95 % interval covered the truth" in panel.summary.object
    assert sum(panel.figure.sources["M"].data["top"]) == 12 and not panel.button.disabled
    # with no earlier study: a note
    fresh = Session(AppState()).build("study")
    fresh._run_part = lambda cfg, params, first: None
    fresh.run()
    fresh._cancelled(None)
    assert "cancelled before its first seeds" in fresh.summary.object


def test_a_study_failing_midway_keeps_its_seeds_and_says_why(monkeypatch):
    import eha_app.sections.study as study_module
    from eha_core.errors import ComputationError

    calls = []

    class Child:
        def call(self, fn, *args, cancel=None, progress=None, total=0, give_way=None, **kwargs):
            calls.append(1)
            if len(calls) == 2:
                raise ComputationError("the server's process for long computations stopped during this run")
            return fn(*args, cancel=cancel, **kwargs)

    monkeypatch.setattr(study_module, "background_process", lambda: Child())
    panel = Session(AppState()).build("study")
    panel.CHUNK_SEEDS = {**panel.CHUNK_SEEDS, "lse": 5}
    panel.form.values = {**panel.form.values, "study_seeds": "12"}
    panel.run()
    assert "The study failed" in panel.status.object and "stopped during this run" in panel.status.object
    assert panel.result.n_completed == 5 and panel.result.cancelled
    assert sum(panel.figure.sources["M"].data["top"]) == 5 and "covered the truth" in panel.summary.object
    assert not panel.button.disabled and panel.cancel_button.disabled


def test_the_study_is_marked_out_of_date_like_every_result():
    state = AppState()
    panel = Session(state).build("study")
    panel.form.values = {**panel.form.values, "study_seeds": "5"}
    assert panel.view.status == "empty"
    panel.run()
    assert panel.view.is_current and not panel.is_stale()
    state.set_text("M", "6000")
    assert panel.is_stale() and "tab 1 changed since this run (M 4000 → 6000 kg)" in panel.view.banner.object
    state.set_text("M", "4000")
    assert panel.view.is_current
    panel.form.values = {**panel.form.values, "study_first": "3"}
    assert panel.is_stale() and "the settings changed" in panel.view.banner.object


def test_tab_1_changing_params_and_validity_together_marks_the_study():
    """A change of both tab 1's parameters and its validity in one step (a settings file) reaches the
    study's mark (its watcher takes several events at once)."""
    state = AppState()
    panel = Session(state).build("study")
    panel.form.values = {**panel.form.values, "study_seeds": "5"}
    panel.run()
    with state.param.update(valid=False):
        state.set_text("M", "7000")
    assert panel.is_stale()
