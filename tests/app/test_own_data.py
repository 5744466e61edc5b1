"""The student's own data: the app's exports read back give the same estimates; bad files get their message."""

import json

import numpy as np
import pytest

from eha_app.session import Session
from eha_app.session.state import AppState


def upload(lse, blob: bytes, filename: str):
    lse._upload = (blob, filename)
    return lse.read_upload()


@pytest.fixture(scope="module")
def simulated():
    lse = Session(AppState()).build("least_squares")
    lse.run()
    return lse, dict(lse.result.estimates)


@pytest.mark.parametrize("kind", ["csv", "mat"])
def test_exported_data_uploaded_again_gives_the_same_estimates(simulated, kind):
    exported, estimates = simulated
    blob = exported.data_bytes(kind)
    lse = Session(AppState()).build("least_squares")
    upload(lse, blob, f"eha_lse_data.{kind}")
    assert lse.own_data is not None and "Using your data" in lse.upload_note.object
    lse.run()
    for k, v in estimates.items():
        np.testing.assert_allclose(lse.result.estimates[k], v, rtol=1e-6, atol=1e-6, err_msg=k)
    assert "not re-simulated" in lse.table.object
    lse.use_simulated()
    assert lse.own_data is None and lse.view.status == "stale"


def test_estimates_download_as_csv_and_json(simulated):
    lse, estimates = simulated
    rows = json.loads(lse.estimates_bytes("json"))["estimates"]
    assert {r["parameter"]: r["estimate"] for r in rows} == pytest.approx(estimates)
    assert all(r["ci95_low"] <= r["estimate"] <= r["ci95_high"] for r in rows)
    header = lse.estimates_bytes("csv").decode().splitlines()[0]
    assert header == "parameter,symbol,unit,estimate,std_error,ci95_low,ci95_high,nominal"
    # the data behind the plot: the measurements and the model re-simulated with the estimates
    from eha_core.data import read_data

    back = read_data(lse.data_bytes("csv"), ("t", "x", "x_resim", "p1_resim"), filename="d.csv")
    np.testing.assert_allclose(back["x_resim"], lse.last_resim.x, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(back["x_resim"], back["x"], atol=1e-6)      # noise-free: the estimates are right


def test_a_file_with_other_column_names_is_mapped(simulated):
    exported, estimates = simulated
    header = "t[s],x[m],v[m/s],p1[Pa],p2[Pa],u[V]"             # the export names its units
    assert exported.data_bytes("csv").decode().startswith(header)
    text = exported.data_bytes("csv").decode().replace(header, "time,pos,vel,pa,pb,cmd", 1)
    lse = Session(AppState()).build("least_squares")
    upload(lse, text.encode(), "lab.csv")
    assert lse.own_data is None and lse.mapping.visible
    question = lse.mapping.objects[0].object
    assert "Which columns of lab.csv are which?" in question and "is not allowed" not in question
    # every column guessed from its name, for the student to check
    assert {c: s.value for c, s in lse.mapping_selects.items()} == dict(
        zip(("t", "x", "v", "p1", "p2", "u"), ("time", "pos", "vel", "pa", "pb", "cmd"), strict=True))
    # while the file waits, the run does not quietly use the simulated sensors
    assert lse.button.disabled and "waits for your file's columns" in lse.notice.object
    assert lse.run() is None and lse.result is None
    lse.mapping_button.clicks += 1
    assert lse.own_data is not None and not lse.mapping.visible and not lse.button.disabled
    lse.run()
    np.testing.assert_allclose(lse.result.estimates["M"], estimates["M"], rtol=1e-6)


def test_names_and_units_of_a_lab_file_are_guessed_and_converted(simulated):
    """time, position[mm], velocity[mm/s], pA[bar], pB[bar], valve[V]: guessed, converted to SI, and the
    result reads as the student's own record (no nominal or paper column, one status sentence)."""
    import io

    import pandas as pd

    exported, estimates = simulated
    df = pd.read_csv(io.BytesIO(exported.data_bytes("csv")))
    df.columns = [c.split("[")[0] for c in df.columns]          # t[s], x[m], ...: SI
    lab = pd.DataFrame({"time": df["t"], "position[mm]": df["x"] * 1e3, "velocity[mm/s]": df["v"] * 1e3,
                        "pA[bar]": df["p1"] / 1e5, "pB[bar]": df["p2"] / 1e5, "valve[V]": df["u"]})
    lse = Session(AppState()).build("least_squares")
    upload(lse, lab.to_csv(index=False, float_format="%.17g").encode(), "lab.csv")
    assert {c: s.value for c, s in lse.mapping_selects.items()} == {
        "t": "time", "x": "position[mm]", "v": "velocity[mm/s]", "p1": "pA[bar]", "p2": "pB[bar]", "u": "valve[V]"}
    assert "All guessed from the names and units" in lse.mapping.objects[0].object
    lse.mapping_button.clicks += 1
    lse.run()
    np.testing.assert_allclose(lse.result.estimates["M"], estimates["M"], rtol=1e-6)
    table = lse.table.object
    assert "<th>nominal</th>" not in table and "<th>paper</th>" not in table and "rel. error" not in table
    assert "Identified in" in table and "re-simulated in" not in table


@pytest.mark.parametrize("content, message", [
    (b"t,x,v,p1,p2,u\n0,0,0,1.2e7,1.8e7,abc\n", "column u, row 1 (line 2): &#x27;abc&#x27; is not a number"),
    (b"t,x,v,p1,p2,u\n" + b"".join(b"%g,0,0,1.2e7,1.8e7,1\n" % (k * 1e-3) for k in range(10)),
     "10 rows of data; need at least 50"),
    (b"t,x,v,p1,p2,u\n" + b"".join(b"%g,0,0,1.2e7,1.8e7,1\n" % (k * 1e-3 + (k > 30) * 5e-4) for k in range(60)),
     "column t, row 32 (line 33): the sampling is not uniform"),
])
def test_malformed_uploads_get_their_message(content, message):
    lse = Session(AppState()).build("least_squares")
    upload(lse, content, "bad.csv")
    assert lse.own_data is None
    assert "your file = &#x27;bad.csv&#x27; is not allowed" in lse.upload_note.object
    assert message in lse.upload_note.object


def test_frequency_downloads():
    from eha_core.data import read_data

    panel = Session(AppState()).build("frequency")
    panel.run()
    for kind in ("csv", "mat"):
        back = read_data(panel.downloads[0 if kind == "csv" else 1].callback().read(), ("t", "r", "x", "u"),
                         filename=f"loop.{kind}")
        np.testing.assert_allclose(back["x"], panel.result.data.x, rtol=1e-9, atol=1e-15)
    by_class = {d.css_classes[0]: d for d in panel.downloads}
    est = json.loads(by_class["eha-dl-freq-json"].callback().read())
    assert by_class["eha-dl-freq-est-csv"].callback().read().startswith(b"coefficient,")
    assert by_class["eha-dl-freq-bode"].callback().read().startswith(b"curve,w_rad_s")
    assert est["estimate"]["den"] == pytest.approx(list(panel.result.estimate.den))
    assert est["settings"]["kp"] == 10.0 and est["validation_fit_percent"] > 90


def test_sensor_noise_changes_the_estimates_reproducibly():
    lse = Session(AppState()).build("least_squares")
    lse.run()
    clean = dict(lse.result.estimates)
    lse.form.values = {**lse.form.values, "lse_noise_p": "0.05", "lse_noise_v": "0.2"}
    assert lse.view.status == "stale"
    lse.run()
    noisy = dict(lse.result.estimates)
    assert abs(noisy["M"] / clean["M"] - 1) > 1e-4                    # the noise shows in the estimates
    assert lse.result.std_errors["M"] > 0
    lse.run()
    assert lse.result.estimates == pytest.approx(noisy)               # seeded: the same draw again
    lse.form.values = {**lse.form.values, "lse_noise_p": "-1"}
    assert "σ p = -1 is not allowed" in lse.form.errors["lse_noise_p"] and lse.button.disabled


def test_a_time_range_of_the_own_record(simulated):
    exported, estimates = simulated
    lse = Session(AppState()).build("least_squares")
    upload(lse, exported.data_bytes("csv"), "run.csv")
    assert lse.window_box.visible
    lse.window_form.values = {"own_from": "1", "own_to": "4"}
    lse.run()
    assert lse.last_data.t[0] == pytest.approx(1.0) and lse.last_data.t[-1] == pytest.approx(4.0)
    assert "t in [1, 4] s" in lse.table.object and "3001 samples" in lse.table.object
    np.testing.assert_allclose(lse.result.estimates["M"], estimates["M"], rtol=1e-3)   # the same actuator
    lse.window_form.values = {"own_from": "4.99", "own_to": ""}
    assert "holds 11 samples; need at least 50" in lse.window_form.errors["own_from"] and lse.button.disabled
    lse.window_form.values = {"own_from": "7", "own_to": ""}
    assert "your record runs from 0 to 5 s" in lse.window_form.errors["own_from"]
    assert lse.view.status == "stale"


@pytest.fixture(scope="module")
def closed_loop():
    """The frequency panel's own experiment: its record (t, r, x, u) as CSV and .mat, and its estimate."""
    source = Session(AppState()).build("frequency")
    source.run()
    return source


def _upload_record(panel, blob: bytes, filename: str):
    panel.record.upload.filename = filename
    panel.record.upload.value = blob
    return panel.record


def test_a_transfer_function_from_the_students_own_record(closed_loop):
    panel = Session(AppState()).build("frequency")
    record = _upload_record(panel, closed_loop.data_bytes("csv"), "loop.csv")   # t, r, x, u: r/x understood
    assert "Your record: loop.csv, 1000 samples every 10 ms, t from 0 to 9.99 s" in record.note.object
    # the record is drawn as soon as it is read: as in the file, and as it will be estimated
    fig = record.data_figure
    assert record.data_area.visible and len(fig.raw.data["t"]) == 1000 and len(fig.used.data["t"]) == 1000
    assert not fig.trend_shown and not fig.model_label and "removed trend" not in fig.legend.text
    assert fig.splits[0].location == pytest.approx(6.67)          # validation starts at sample 667
    record.run()
    rec = record.result
    assert rec.n_estimation == 667 and rec.estimate.fit_percent > 90 and rec.validation.fit_percent > 85
    assert "Validated on the last 333 samples" in record.summary.object
    assert record.view.status == "current" and len(record.bode.points.data["w"]) > 10
    assert "of your record" in record.bode.data_item.label["value"]
    # after the estimate, its output is drawn over the record (estimation part, then validation)
    assert "validation" in fig.model_label and fig.model_label in fig.legend.text
    assert len(fig.model.data["t"]) == 1000
    record.detrend.value = "mean"
    assert record.view.status == "stale"


def test_preprocessing_is_drawn_on_the_record_and_checked(closed_loop):
    panel = Session(AppState()).build("frequency")
    record = _upload_record(panel, closed_loop.data_bytes("csv"), "loop.csv")
    x = closed_loop.result.data.x
    record.detrend.value = "linear"
    fig = record.data_figure
    assert fig.trend_shown and "removed trend" in fig.legend.text
    used_y = np.asarray(fig.used.data["y"], dtype=float)
    trend_y = np.asarray(fig.trend.data["y"], dtype=float)
    np.testing.assert_allclose(used_y + trend_y, x, atol=1e-6)           # drawn: what is used + what is removed
    k = np.arange(x.size)
    assert abs(np.polyfit(k, used_y, 1)[0]) < 1e-9                      # no trend left
    record.window_form.values = {"rec_from": "2", "rec_to": "8"}
    assert record.prepared.t[0] == pytest.approx(2.0) and record.prepared.t[-1] == pytest.approx(8.0)
    assert "Estimation on t ∈ [2, 6.01] s" in fig.note.text and "a linear trend removed" in fig.note.text
    record.run()
    assert record.result.t.size == 601 and record.result.prepared.detrend == "linear"
    assert "(t ∈ [2, 6.01] s)" in record.summary.object and "A linear trend was removed" in record.summary.object
    record.window_form.values = {"rec_from": "2", "rec_to": "99"}
    assert record.window_form.errors == {
        "rec_to": "to t = 99 is not allowed: your record runs from 0 to 9.99 s"}
    assert record.button.disabled and record.view.status == "stale"
    record.window_form.values = {"rec_from": "9.9", "rec_to": ""}
    assert "holds 10 samples; need at least 30" in record.window_form.errors["rec_from"]


def test_a_record_with_other_column_names_is_mapped(closed_loop):
    from eha_core.data import write_data

    d = closed_loop.result.data
    blob = write_data({"time": d.t, "cmd": d.r, "pos": d.x}, "csv", units={"pos": "mm"})
    panel = Session(AppState()).build("frequency")
    record = _upload_record(panel, blob, "lab.csv")
    assert record.columns is None and record.mapping.panel.visible
    question = record.mapping.panel.objects[0].object
    assert "Which columns of lab.csv are which?" in question and "is not allowed" not in question
    # the question once, beside the upload: the note above it does not repeat it
    assert record.note.object == "" and record.button.disabled
    assert {c: s.value for c, s in record.mapping.selects.items()} == {"t": "time", "u": "cmd", "y": "pos[mm]"}
    record.mapping.selects["t"].value = "time"
    record.mapping.selects["u"].value = "cmd"
    record.mapping.selects["y"].value = "pos[mm]"
    record.mapping.button.clicks += 1
    assert record.columns is not None and not record.mapping.panel.visible
    np.testing.assert_allclose(record.columns[2], d.x, rtol=1e-9)       # mm read back as m
    record.run()
    direct = _upload_record(Session(AppState()).build("frequency"), closed_loop.data_bytes("mat"),
                            "loop.mat")
    direct.run()                                                        # the .mat export, read by name
    # two iterative estimates of records that differ by the mm rounding: each stops within ~3e-4 standard
    # errors of the minimum (tol = 1e-10; they differ by up to 2e-5 of one, 3e-7 relative, with OpenBLAS's kernels)
    e, f = record.result.estimate, direct.result.estimate
    assert e.den[0] == f.den[0] == 1.0
    np.testing.assert_array_less(np.abs(e.den[1:] - f.den[1:]), 1e-3 * f.param_std[:f.n_poles])
    settings = json.loads(record.estimate_bytes("json"))["settings"]
    assert settings["columns"] == {"t": "time", "u": "cmd", "y": "pos[mm]"} and settings["file"] == "lab.csv"


def test_a_record_without_the_columns_gets_its_message():
    panel = Session(AppState()).build("frequency")
    record = _upload_record(panel, b"t,u\n0,1\n", "bad.csv")
    question = record.mapping.panel.objects[0].object
    assert "It has t, u, not all named t, u, y. Guessed 2 of 3 from the names and units; choose output y" in question
    record.mapping.selects["t"].value = "t"
    record.mapping.selects["u"].value = "u"
    record.mapping.button.clicks += 1                                 # y still missing: the reader says so
    assert "no column y: the file has t, u" in record.note.object and record.columns is None
    _upload_record(panel, b"t,u,y\n0,1,2\n0.1,nan,3\n", "nan.csv")
    assert "column u" in record.note.object and "row" in record.note.object


def test_the_estimate_and_the_bode_curves_download(closed_loop):
    import csv
    import io

    rows = list(csv.DictReader(io.StringIO(closed_loop.estimate_bytes("csv").decode())))
    e = closed_loop.result.estimate
    assert [r["coefficient"] for r in rows] == ["a1", "a2", "a3", "b0", "input_offset"]
    assert float(rows[2]["value"]) == pytest.approx(e.den[3], rel=1e-9)
    lo, hi, v = float(rows[0]["ci95_low"]), float(rows[0]["ci95_high"]), float(rows[0]["value"])
    assert lo < v < hi and (hi - lo) / 2 == pytest.approx(1.959964 * e.param_std[0], rel=1e-6)
    est = json.loads(closed_loop.estimate_bytes("json"))
    assert est["coefficients"] == json.loads(json.dumps(est["coefficients"])) and est["fit_percent"] > 90
    bode = list(csv.DictReader(io.StringIO(closed_loop.bode_bytes().decode())))
    curves = {r["curve"] for r in bode}
    assert {"estimate", "linearised_eq24"} <= curves and curves & {"etfe", "spectral"}
    first = next(r for r in bode if r["curve"] == "estimate")
    assert float(first["magnitude_db"]) == pytest.approx(closed_loop.result.bode.estimate.magnitude_db[0], rel=1e-8)


def test_an_exercise_leaves_eq24_out_of_the_bode_curves(closed_loop):
    import dataclasses

    state = AppState()
    state.secret = {"M": 4000.0, "B": 1000.0}
    panel = Session(state).build("frequency")
    panel.result = dataclasses.replace(closed_loop.result)
    curves = {line.split(",")[0] for line in panel.bode_bytes().decode().splitlines()[1:]}
    assert "linearised_eq24" not in curves and "estimate" in curves


def test_the_record_bode_has_no_eq24_entry(closed_loop):
    panel = Session(AppState()).build("frequency")
    record = _upload_record(panel, closed_loop.data_bytes("csv"), "loop.csv")
    record.run()
    assert not record.bode.theory_item.visible                  # nothing is known of a record's plant
    closed_loop._shown.add("bode")
    closed_loop._draw("bode")
    assert closed_loop.figures["bode"].theory_item.visible


def test_all_figures_data_download(closed_loop):
    import dataclasses
    import io
    import zipfile

    import scipy.io

    from eha_core.data import read_data

    z = zipfile.ZipFile(io.BytesIO(closed_loop.figures_bytes()))
    names = set(z.namelist())
    assert {"fig8_excitation.csv", "fig9_closed_loop.csv", "fig11_fit.csv", "fig12_bode_curves.csv",
            "fig12_bode_data_points.csv", "fig13_validation.csv", "residuals_autocorrelation.csv",
            "residuals_cross_correlation.csv", "figures.mat"} == names
    fi = closed_loop.result
    fit = read_data(z.read("fig11_fit.csv"), ("t", "x", "x_estimate", "x_eq24"), filename="fig11_fit.csv")
    np.testing.assert_allclose(fit["x_estimate"], fi.estimate_output, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(fit["x_eq24"], fi.theoretical_comparison.y_hat, rtol=1e-9, atol=1e-15)
    mat = scipy.io.loadmat(io.BytesIO(z.read("figures.mat")))
    np.testing.assert_allclose(mat["fig13_validation_x_estimate"].ravel(), fi.validation.y_hat, rtol=1e-12)
    np.testing.assert_allclose(mat["fig12_bode_curves_estimate_db"].ravel(), fi.bode.estimate.magnitude_db)
    # an exercise: nothing computed from the hidden values
    state = AppState()
    state.secret = {"M": 4000.0}
    panel = Session(state).build("frequency")
    panel.result = dataclasses.replace(fi)
    z = zipfile.ZipFile(io.BytesIO(panel.figures_bytes()))
    assert b"eq24" not in z.read("fig11_fit.csv") and b"eq24" not in z.read("fig12_bode_curves.csv")
    assert not any("eq24" in k for k in scipy.io.loadmat(io.BytesIO(z.read("figures.mat"))))


def test_a_changed_record_never_shows_the_old_estimate(closed_loop):
    panel = Session(AppState()).build("frequency")
    record = _upload_record(panel, closed_loop.data_bytes("csv"), "loop.csv")
    record.run()
    fig = record.data_figure
    assert fig.model_label
    record.detrend.value = "mean"                 # prepared again: the old estimate is not drawn over it
    assert record.view.status == "stale" and not fig.model_label and len(fig.model.data["t"]) == 0
    record.detrend.value = "none"                 # back to what it was estimated from: drawn again
    assert record.view.status == "current" and fig.model_label
    # another file with the same name and length: not the estimate's data
    from eha_core.data import write_data

    d = closed_loop.result.data
    _upload_record(panel, write_data({"t": d.t, "r": d.r, "x": 2 * d.x}, "csv"), "loop.csv")
    assert record.result is None and record.view.status == "stale" and not fig.model_label
    assert all(dl.disabled for dl in record.downloads)


def test_the_records_estimate_takes_the_forms_delay(closed_loop):
    panel = Session(AppState()).build("frequency")
    record = _upload_record(panel, closed_loop.data_bytes("csv"), "loop.csv")
    record.run()
    assert record.view.status == "current"
    panel.form.values = {**panel.form.values, "input_delay": "0.02"}
    assert record.view.status == "stale"                     # the delay is one of its inputs
    record.run()
    assert record.result.estimate.input_delay == 0.02 and "τ = <b>20 ms</b>" in record.summary.object
    settings = json.loads(record.estimate_bytes("json"))
    assert settings["estimate"]["input_delay"] == 0.02


def test_an_excitation_idinput_refuses_holds_the_records_estimate_too(closed_loop):
    """Found by the long random walk (41 times): with an excitation setting idinput refuses shown beside
    its field, "Estimate from your record" stayed enabled and its result current, while a setting the form
    cannot parse disabled both: one rule now, every run of the panel waits for the form's messages."""
    panel = Session(AppState()).build("frequency")
    record = _upload_record(panel, closed_loop.data_bytes("csv"), "loop.csv")
    record.run()
    assert record.view.status == "current" and not record.button.disabled
    before = dict(panel.form.values)
    panel.form.values = {**before, "signal_type": "sine", "n_sines": "5000"}
    assert panel.excitation_errors and panel.form.errors
    assert record.button.disabled and record.view.status == "stale"
    panel.form.values = before
    assert not panel.form.errors and not record.button.disabled and record.view.status == "current"


def test_the_records_button_follows_the_file_read_not_its_drawing(closed_loop):
    """Found by the long random walk (seed 2): the note named the new record while its button waited for
    the record's drawing (a job of its own) to be enabled. (In-process jobs run at once: the drawing is
    held back here.)"""
    panel = Session(AppState()).build("frequency")
    record = panel.record
    held_back = []
    record.preview_runner.run = lambda label, compute, show, **kwargs: held_back.append(show)
    _upload_record(panel, closed_loop.data_bytes("csv"), "loop.csv")
    assert held_back and "Your record: loop.csv" in record.note.object
    assert not record.button.disabled


def test_own_file_results_show_only_what_applies_to_a_file():
    """On the student's own file: the settings that make the simulated record are not shown, every
    physical estimate has a reading, and a file without velocity is told where x alone works."""
    from eha_app.session import Session
    from eha_app.session.state import AppState

    lse = Session(AppState()).build("least_squares")
    lse.run()
    blob = lse.data_bytes("csv")
    own = Session(AppState()).build("least_squares")
    assert "lse_scenario" not in own.form.hidden
    own._upload = (blob, "mine.csv")
    own.read_upload()
    assert {"lse_scenario", "lse_excitation", "lse_seed", "lse_noise_x"} <= set(own.form.hidden)
    own.run()
    table = own.table.object
    assert table.count("eha-reading-estimated") == 5 and table.count(">determined<") == 4   # d0: "estimated"
    assert "Why the constant model fails" not in table
    own.use_simulated()
    assert "lse_scenario" not in own.form.hidden
    header, *rows = blob.decode().splitlines()
    keep = [k for k, name in enumerate(header.split(",")) if not name.startswith("v")]
    no_v = "\n".join(",".join(line.split(",")[k] for k in keep) for line in [header, *rows])
    third = Session(AppState()).build("least_squares")
    third._upload = (no_v.encode(), "no_v.csv")
    third.read_upload()
    assert third.column_mapping.waiting and "x alone works there" in third.column_mapping.panel.objects[0].object
