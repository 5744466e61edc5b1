"""Exercises: a hidden actuator per student, verdicts without the truth, hand-ins that survive."""

import threading

import numpy as np
import pytest

from eha_app.app import ExerciseGate, create_app
from eha_app.runtime.handins import HandIns
from eha_app.session import Session
from eha_app.session.state import AppState
from eha_core.exercise import Exercise, normalize_id

HIDE = ("M", "B", "Af", "beta_e")


@pytest.fixture
def exercise(tmp_path, monkeypatch):
    ex = Exercise.new(hide=HIDE, vary=0.25, tolerance=0.05, title="Lab 3", secret="5a" * 32)   # the same class
    path = tmp_path / "class.json"
    ex.save(path)
    monkeypatch.setenv("EHA_EXERCISE", str(path))
    return ex, path


def test_actuators_are_per_student_deterministic_and_within_the_variation():
    ex = Exercise.new(hide=HIDE, vary=0.25)
    a, a2, b = ex.student_params("s1"), ex.student_params(" S1 "), ex.student_params("s2")
    assert a == a2 and a != b
    for n in HIDE:
        base = getattr(Exercise.new(hide=HIDE, vary=0.0).student_params("x"), n)
        assert 0.75 * base <= getattr(a, n) <= 1.25 * base
    other = Exercise.new(hide=HIDE, vary=0.25)                 # another secret, another class
    assert other.student_params("s1") != a
    assert Exercise.from_json(ex.to_json()).student_params("s1") == a        # the file round-trips


def test_bad_exercise_settings_are_refused_with_their_names():
    with pytest.raises(ValueError, match=r"hide = M,p2_0 is not allowed: p2_0 cannot be hidden"):
        Exercise.new(hide=("M", "p2_0"))
    with pytest.raises(ValueError, match=r"tolerance = B=5% is not allowed: B is not hidden"):
        Exercise.new(hide=("M",), tolerance={"B": 0.05})
    with pytest.raises(ValueError, match=r"feedback = often is not allowed: use verdict, none, after-deadline"):
        Exercise.new(hide=("M",), feedback="often")
    with pytest.raises(ValueError, match=r"vary = 80 % is not allowed"):
        Exercise.new(hide=("M",), vary=0.8)
    with pytest.raises(ValueError, match=r"student id = \(empty\) is not allowed"):
        normalize_id("   ")


def test_two_students_handing_in_at_the_same_moment_lose_nothing(tmp_path):
    store = HandIns(tmp_path / "class.json")
    barrier = threading.Barrier(8)

    def hand_in(k):
        barrier.wait()
        for j in range(10):
            store.add(f"s{k}", {"M": 4000.0 + j}, {"M": j % 2 == 0})

    threads = [threading.Thread(target=hand_in, args=(k,)) for k in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(store.all()) == 80
    latest = store.latest()
    assert [h.student for h in latest] == [f"s{k}" for k in range(8)] and all(h.count == 10 for h in latest)
    assert len(HandIns(tmp_path / "class.json").all()) == 80          # a new connection (a restart) sees them


def test_a_student_identifies_their_actuator_and_hands_in(exercise):
    """An open exercise (no roster): the id typed is taken as given, the actuator is the id's."""
    ex, path = exercise
    state = AppState()
    page = create_app(state)
    gate = page.gate
    assert "ids are not checked" in gate.intro.object
    gate.student_id.value = "  "
    gate.start()
    assert "student id = (empty) is not allowed" in gate.message.object and not state.student
    gate.student_id.value = "Ada"
    gate.start()
    truth = ex.student_params("ada")
    assert state.student == "ada" and state.params == truth
    assert "ada" in HandIns(path).presence()
    tab1 = Session(state).build("parameters")
    shown = tab1.derived.object + str(tab1.form.values) + str(tab1.form.spec)
    for n in HIDE:
        assert n not in tab1.form.values and f"{getattr(truth, n):.4g}" not in shown
    assert "Hidden in this exercise" in tab1.derived.object and "430.1" not in tab1.derived.object
    state.set_text("M", "4000")                                     # not the student's to set
    assert state.params.M == truth.M
    tab3 = Session(state)
    lse = tab3.build("least_squares")
    assert not lse.all_button.visible and lse.handin_button.visible and lse.handin_button.disabled
    assert lse.handin_button.description.startswith("run the least squares first")
    lse.run()
    # the tooltip says what is true now (it said "run the least squares first" after a run)
    assert not lse.handin_button.disabled
    assert lse.handin_button.description.startswith("hand in the estimates of M, B, Af, βe in the table")
    lse.form.values = {**lse.form.values, "lse_seed": "7"}
    assert "from the previous settings" in lse.handin_button.description
    lse.form.values = {**lse.form.values, "lse_seed": "0"}
    assert lse.handin_button.description.endswith("in the table")
    assert "hidden" in lse.table.object and "nominal" not in lse.table.object
    lse.hand_in()
    rows = HandIns(path).all()
    # judged by the standard errors of the student's own record and the route's own error on it
    kept = rows[0].settings
    assert kept["std_errors"] == {n: pytest.approx(lse.result.std_errors[n]) for n in HIDE}
    assert set(kept["model_errors"]) == set(HIDE)
    verdicts = ex.verdicts("ada", lse.result.estimates, kept["std_errors"], kept["model_errors"])
    assert f"{sum(verdicts.values())} of 4 accepted" in lse.verdict.object
    for n in HIDE:
        assert f"{getattr(truth, n):.6g}" not in lse.verdict.object.replace(f"{lse.result.estimates[n]:.5g}", "")
    rows = HandIns(path).all()
    assert [(r.student, r.method) for r in rows] == [("ada", "lse")] and rows[0].verdicts == verdicts
    # the hand-in says how it was obtained: the settings and the data's conditions
    assert rows[0].settings["lse_seed"] == "0" and rows[0].settings["lse_noise_x"] == "0.01"
    assert rows[0].conditions["noise"] == {"x": 1e-5, "v": 1e-3, "p1": 5e4, "p2": 5e4}
    assert rows[0].errors["M"] == pytest.approx(lse.result.estimates["M"] / truth.M - 1)
    freq = tab3.build("frequency")
    freq.run()
    assert "linearised at v = 0" not in freq.summary.object and "Hidden in this exercise" in freq.backout.object


def test_the_default_exercise_is_not_solved_by_one_click(exercise):
    """With `eha exercise new`'s conditions the default least squares err at the level of the sensor
    noise (the noise-free exercise gave the hidden values to five digits), and the intervals say so."""
    ex, _ = exercise
    page = create_app(AppState())
    page.gate.student_id.value = "ada"
    page.gate.start()
    truth = ex.student_params("ada")
    lse = page.session.build("least_squares")
    # the noise floor is the form's lower bound: lowering it is refused beside the field
    lse.form.values = {**lse.form.values, "lse_noise_x": "0"}
    assert "σ x = 0 is not allowed: must lie in [0.01, 10] mm" in lse.request()[1]["lse_noise_x"]
    lse.form.values = {**lse.form.values, "lse_noise_x": "0.01"}
    lse.run()
    res = lse.result
    rel = {n: res.estimates[n] / getattr(truth, n) - 1 for n in HIDE}
    half = {n: (res.ci95[n][1] - res.ci95[n][0]) / 2 / abs(getattr(truth, n)) for n in HIDE}
    assert all(abs(e) > 1e-3 for e in rel.values()), rel                 # no estimate is exact
    assert max(abs(e) for e in rel.values()) > 0.01, rel
    assert all(h > 1e-3 for h in half.values()), half                    # no interval has collapsed
    assert half["B"] > 0.25                                               # the data do not determine B
    # instrumental variables (honest intervals): each error within two of its 95 % half-widths
    # (3.9 standard errors), no interval collapsed
    lse.form.values = {**lse.form.values, "lse_estimator": "iv"}
    lse.run()
    res = lse.result
    for n in HIDE:
        lo, hi = res.ci95[n]
        err = res.estimates[n] - getattr(truth, n)
        assert abs(err) <= hi - lo and (hi - lo) / 2 > 1e-3 * getattr(truth, n), n


def _joined(ex, path, code):
    page = create_app(AppState())
    page.gate.student_id.value = code
    page.gate.start()
    return page


def test_a_roster_student_joins_with_their_code_only(tmp_path, monkeypatch):
    ex = Exercise.new(hide=HIDE, roster=[("s1", "Ada <b>Lovelace</b>"), ("s2", "Alan Turing")])
    path = tmp_path / "class.json"
    ex.save(path)
    monkeypatch.setenv("EHA_EXERCISE", str(path))
    page = create_app(AppState())
    gate = page.gate
    assert "join code" in gate.intro.object and "eha-join-code" in gate.student_id.css_classes
    for typed in ("s1", "Ada Lovelace", "AAAAA-AAAAA"):        # an id, a name or a wrong code: the same answer
        gate.student_id.value = typed
        gate.start()
        assert "it is no code of this exercise" in gate.message.object and not page.session.student
    gate.student_id.value = ex.join_code("s2")
    gate.start()                                            # the fourth try still counts
    assert page.session.student == "s2" and page.session.state.student_name == "Alan Turing"
    from eha_app import app as app_module

    now = [1000.0]
    monkeypatch.setattr(app_module, "_wrong_codes", app_module.WrongCodes(clock=lambda: now[0]))
    page = create_app(AppState())
    gate = page.gate
    gate.address = "10.0.0.7"
    for _ in range(ExerciseGate.FREE_TRIES):
        gate.student_id.value = "ZZZZZ-ZZZZZ"
        gate.start()
    gate.student_id.value = ex.join_code("s1").lower().replace("-", " ")
    gate.start()                                            # too many wrong codes: the page waits
    assert "Too many wrong codes" in gate.message.object and not page.session.student
    # a new page (a reload) from the same address waits too: the count is the address's, not the page's
    page = create_app(AppState())
    gate = page.gate
    gate.address = "10.0.0.7"
    gate.student_id.value = ex.join_code("s1")
    gate.start()
    assert "Too many wrong codes" in gate.message.object and not page.session.student
    other = create_app(AppState()).gate                     # another computer is not held up
    other.address = "10.0.0.8"
    other.student_id.value = ex.join_code("s2")
    other.start()
    assert other.state.student == "s2"
    now[0] += ExerciseGate.WAIT_S + 0.1
    gate.start()
    assert page.session.student == "s1"
    header = page.layout.objects[1].object
    assert "Ada &lt;b&gt;Lovelace&lt;/b&gt;" in header and "<b>Lovelace" not in header      # escaped


def test_attempts_deadline_closing_and_feedback_hold_at_hand_in(tmp_path, monkeypatch):
    ex = Exercise.new(hide=("M",), roster=[("s1", "Ada")], attempts=2, feedback="none")
    path = tmp_path / "class.json"
    ex.save(path)
    monkeypatch.setenv("EHA_EXERCISE", str(path))
    page = _joined(ex, path, ex.join_code("s1"))
    lse = page.session.build("least_squares")
    lse.run()
    for k in (1, 2):
        lse.hand_in()
        box = lse.verdict.object
        assert f"hand-in {k} of 2 allowed" in box and "within" not in box and "Your teacher will tell you" in box
    lse.hand_in()
    assert "Not handed in: you have handed in 2 of 2 times allowed" in lse.verdict.object
    assert len(HandIns(path).all()) == 2
    # the teacher closes hand-ins; a deadline passed (a new exercise file: attempts unlimited)
    ex2 = ex.replace(attempts=0, deadline="2020-01-01T00:00", feedback="after-deadline")
    ex2.save(path)
    lse.state.exercise = ex2
    lse.hand_in()
    assert "Not handed in: the deadline (2020-01-01T00:00) has passed" in lse.verdict.object
    store = HandIns(path)
    store.set_control("deadline", "2100-01-01T00:00")       # extended by the teacher
    lse.hand_in()
    assert "hand-in 3" in lse.verdict.object and "shown after the deadline" in lse.verdict.object
    store.set_control("open", "0")
    lse.hand_in()
    assert "Not handed in: hand-ins are closed by your teacher" in lse.verdict.object
    assert len(store.all()) == 3


def test_concurrent_hand_ins_of_one_student_cannot_pass_the_attempts(tmp_path):
    ex = Exercise.new(hide=("M",), attempts=3)
    store = HandIns(tmp_path / "class.json").check()
    barrier = threading.Barrier(8)
    outcome = []

    def hand_in():
        barrier.wait()
        try:
            store.add("s1", {"M": 1.0}, {"M": False}, refusal=lambda count, control: ex.refusal(count))
            outcome.append("stored")
        except Exception as exc:           # noqa: BLE001
            outcome.append(type(exc).__name__)

    threads = [threading.Thread(target=hand_in) for _ in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert sorted(outcome) == ["Refused"] * 5 + ["stored"] * 3 and len(store.all()) == 3


def test_without_an_exercise_the_app_is_as_before(monkeypatch):
    monkeypatch.delenv("EHA_EXERCISE", raising=False)
    page = create_app(AppState())
    assert not hasattr(page, "eha_gate") and page.session.state.params.M == 4000.0


def test_the_harmonic_disturbance_model_in_an_exercise(exercise):
    """Found by the random walk (seed 404): the exercise's table of a harmonic model wrote the nominal value
    of the sinusoid's amplitudes, which has none, raised, and left the page broken."""
    ex, _ = exercise
    page = create_app(AppState())
    page.gate.student_id.value = "ada"
    page.gate.start()
    lse = page.session.build("least_squares")
    lse.form.values = {**lse.form.values, "lse_model": "harmonic"}
    lse.run()
    assert not lse.alert.visible and "hidden" in lse.table.object and "<table" in lse.table.object
    assert len([k for k in lse.result.estimates if k not in HIDE]) > len(("d0",))   # the amplitudes too


def test_the_frequency_route_hands_in_the_back_outs_beta_e_with_the_students_own_values(exercise):
    ex, path = exercise
    page = create_app(AppState())
    page.gate.student_id.value = "ada"
    page.gate.start()
    truth = ex.student_params("ada")
    freq = page.session.build("frequency")
    assert freq.form.values["noise_x"] == "0.01" and freq.handin_button.visible and freq.handin_button.disabled
    freq.form.values = {**freq.form.values, "noise_x": "0.001"}
    assert "σ x = 0.001 is not allowed: must lie in [0.01, 10] mm" in freq.config()[1]["noise_x"]
    freq.form.values = {**freq.form.values, "noise_x": "0.01", "n_samples": "7000"}
    freq.run()                                   # 7000 × 0.01 s = 70 s: longer than the exercise's 60 s
    assert "N × Ts = 70 s is not allowed: this exercise's records are at most 60 s" in freq.alert.object
    freq.form.values = {**freq.form.values, "n_samples": "1000"}
    freq.run()
    assert freq.result.config.noise_x == 1e-5 and "M = the paper's value" in freq.handin_button.description
    lse = page.session.build("least_squares")
    lse.run()
    freq._handin_tip()
    assert "M = your least-squares estimate" in freq.handin_button.description
    freq.hand_in()
    row = HandIns(path).all()[-1]
    assert row.method == "frequency" and set(row.estimates) == {"beta_e"}
    assert row.settings["assumed"]["M"] == pytest.approx(lse.result.estimates["M"])
    assert row.settings["beta_e_from"] == "beta_e_from_stiffness" and row.conditions["noise"]["x"] == 1e-5
    # the value is eq. 27b-d's with the student's M: β_e scales with the M assumed (the page's back-out, run
    # before the least squares, took the paper's 4000 kg and says so)
    assert freq.result.backout.known["M"] == 4000.0 and "M = 4000 kg" in freq.backout.object
    assert row.estimates["beta_e"] == pytest.approx(
        freq.result.backout.beta_e_from_stiffness * lse.result.estimates["M"] / 4000.0, rel=1e-9)
    assert f"{truth.M:.4g}" not in freq.backout.object
    assert "from the transfer function and back-out" in freq.verdict.object


def test_every_record_of_the_students_actuator_is_measured_through_noisy_sensors(exercise):
    """Tab 2's curves and downloads carry the exercise's sensor noise from the first draw: noise-free
    records of the hidden actuator would let a student fit it exactly away from the app."""
    ex, _ = exercise
    page = create_app(AppState())
    page.gate.student_id.value = "ada"
    page.gate.start()
    sim = page.session.build("simulation")
    sim._build_plots()
    assert sim.form.values["sensor_x"] == "0.01" and sim.form.values["sensor_p"] == "0.05"
    assert sim.results and all(r.label.endswith("+ sensor noise") for r in sim.results)
    assert sim.view.status == "current"
    sim.form.values = {**sim.form.values, "sensor_v": "0"}
    assert "sensor σ v = 0 is not allowed: must lie in [1, 1000] mm/s" in sim.request()[1]["sensor_v"]
    sim.form.values = {**sim.form.values, "sensor_v": "1"}
    sim.run("both")
    assert all(r.label.endswith("+ sensor noise") for r in sim.results) and len(sim.results) == 8


def test_tab_2_opened_while_tab_1_is_not_valid_marks_its_first_draw_out_of_date(exercise):
    """In an exercise tab 2's first draw is the student's actuator through its sensors; opened while a
    field of tab 1 is not valid, it is drawn from the last valid values and marked so (it said current;
    found by the random walk, seed 9 with --exercise)."""
    page = create_app(AppState())
    page.gate.student_id.value = "ada"
    page.gate.start()
    page.session.state.set_text("p1_0", "inf")
    sim = page.show("simulation")
    assert sim.results and sim.view.status == "stale"
    page.session.state.set_text("p1_0", "0")
    assert sim.view.status in ("current", "updating")


def test_the_reveal_shows_each_student_their_truth_and_errors_and_no_one_elses(tmp_path, monkeypatch):
    ex = Exercise.new(hide=("M", "beta_e"), roster=[("s1", "Ada"), ("s2", "Alan")], feedback="after-deadline",
                      deadline="2100-01-01T00:00", secret="7c" * 32)
    path = tmp_path / "class.json"
    ex.save(path)
    monkeypatch.setenv("EHA_EXERCISE", str(path))
    pages = {s: _joined(ex, path, ex.join_code(s)) for s in ("s1", "s2")}
    lse = pages["s1"].session.build("least_squares")
    lse.run()
    lse.hand_in()
    assert "shown after the deadline" in lse.verdict.object and "within" not in lse.verdict.object
    for page in pages.values():
        page.check_result()
        assert not page.result_pane.visible
    store = HandIns(path)
    store.set_control("deadline", "2020-01-01T00:00")        # the deadline has passed: the verdicts, no truth
    pages["s1"].check_result()
    text = pages["s1"].result_pane.object
    truth = {s: ex.student_params(s) for s in ("s1", "s2")}
    assert "The deadline has passed" in text and ("✓" in text or "✗" in text)
    assert f"{truth['s1'].M:.5g}" not in text
    store.set_control("revealed", "1")
    for s, page in pages.items():
        page.check_result()
        text = page.result_pane.object
        assert page.result_pane.visible and f"M = {truth[s].M:.5g} kg" in text
        other = "s2" if s == "s1" else "s1"
        assert f"{truth[other].M:.5g}" not in text
    err = ex.errors("s1", lse.result.estimates)["M"]
    assert f"({100 * err:+.2f} %)" in pages["s1"].result_pane.object
    assert "You handed nothing in" in pages["s2"].result_pane.object


def test_a_user_signed_in_by_an_identity_provider_gets_their_roster_actuator(tmp_path, monkeypatch):
    """Panel's OAuth (eha serve --oauth-provider ...): pn.state.user is the roster's id; no code is asked."""
    import panel as pn

    ex = Exercise.new(hide=HIDE, roster=[("ada@uni.example", "Ada"), ("s2", "Alan")], secret="42" * 32)
    path = tmp_path / "class.json"
    ex.save(path)
    monkeypatch.setenv("EHA_EXERCISE", str(path))
    monkeypatch.setattr(type(pn.state), "user", property(lambda self: "Ada@Uni.example"))
    monkeypatch.setattr(pn.config, "oauth_provider", "generic")
    page = create_app(AppState())
    assert page.session.student == "ada@uni.example" and page.session.state.student_name == "Ada"
    assert page.session.state.params == ex.student_params("ada@uni.example")
    monkeypatch.setattr(type(pn.state), "user", property(lambda self: "mallory"))
    page = create_app(AppState())
    assert not page.session.student and page.gate.button.disabled
    assert "signed in as mallory, who is not in this exercise's roster" in page.gate.message.object
    # without a provider, Panel's guest cookie (any page can set it) names no one
    monkeypatch.setattr(pn.config, "oauth_provider", None)
    monkeypatch.setattr(type(pn.state), "user", property(lambda self: "ada@uni.example"))
    page = create_app(AppState())
    assert not page.session.student and not page.gate.button.disabled


def test_signals_an_exercise_does_not_measure_are_not_in_a_students_records(tmp_path, monkeypatch):
    from eha_core.exercise import Conditions

    ex = Exercise.new(hide=("M", "B"), conditions=Conditions(measured=("x", "p1", "p2"), disturbance="sine:300:1"),
                      secret="99" * 32)
    path = tmp_path / "class.json"
    ex.save(path)
    monkeypatch.setenv("EHA_EXERCISE", str(path))
    page = create_app(AppState())
    page.gate.student_id.value = "ada"
    page.gate.start()
    sim = page.session.build("simulation")
    sim._build_plots()
    r = sim.results[0]
    assert np.allclose(r.v, np.gradient(r.x, r.t)) and "(x, p1, p2 measured)" in r.label
    lse = page.session.build("least_squares")
    lse.run()
    assert lse.last_data.source.endswith("v from dx/dt") and lse.last_conditions["v"] == "dx/dt of the measured x"
    assert "sine:300:1 (the exercise's)" in lse.last_conditions["disturbance_applied"]
    freq = page.session.build("frequency")
    assert freq.config()[0].disturbance == "sine:300:1"
    ex2 = ex.replace(conditions=Conditions(measured=("x", "v")))
    ex2.save(path)
    page = create_app(AppState())
    page.gate.student_id.value = "bob"
    page.gate.start()
    sim = page.session.build("simulation")
    sim._build_plots()
    assert np.isnan(sim.results[0].p1).all()
    lse = page.session.build("least_squares")
    lse.run()
    assert "the least squares need p1 and p2, which this exercise does not measure" in lse.alert.object


def test_the_boards_record_and_plant_step_are_measured_through_the_exercises_sensors(exercise):
    from eha_core.board import nonlinear_step, validation_record

    ex, _ = exercise
    page = create_app(AppState())
    page.gate.student_id.value = "ada"
    page.gate.start()
    board = page.session.build("board")
    assert board._measured() == (1e-5, "none")
    truth = ex.student_params("ada")
    clean = validation_record(truth, seed=1)
    noisy = validation_record(truth, seed=1, noise_x=1e-5)
    assert 0.8e-5 < np.std(noisy.x - clean.x) < 1.2e-5
    step = nonlinear_step(truth, 10.0, 0.01, noise_x=1e-5)
    assert step.source.endswith("measured") and 0.8e-5 < np.std(step.y - nonlinear_step(truth, 10.0, 0.01).y) < 1.2e-5
