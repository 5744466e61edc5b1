"""The student's own data: the app's exports read back give the same estimates; bad files get their message."""

import json

import numpy as np
import pytest

from eha_app.state import AppState
from eha_app.tabs.identification import IdentificationTab


def upload(lse, blob: bytes, filename: str):
    lse._upload = (blob, filename)
    return lse.read_upload()


@pytest.fixture(scope="module")
def simulated():
    lse = IdentificationTab(AppState()).lse
    lse.run()
    return lse, dict(lse.result.estimates)


@pytest.mark.parametrize("kind", ["csv", "mat"])
def test_exported_data_uploaded_again_gives_the_same_estimates(simulated, kind):
    exported, estimates = simulated
    blob = exported.data_bytes(kind)
    lse = IdentificationTab(AppState()).lse
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
    assert header == "parameter,estimate,std_error,ci95_low,ci95_high,nominal"


def test_a_file_with_other_column_names_is_mapped(simulated):
    exported, estimates = simulated
    text = exported.data_bytes("csv").decode().replace("t,x,v,p1,p2,u", "time,pos,vel,pa,pb,cmd", 1)
    lse = IdentificationTab(AppState()).lse
    upload(lse, text.encode(), "lab.csv")
    assert lse.own_data is None and lse.mapping.visible
    assert "no column t, x, v, p1, p2, u: the file has time, pos, vel, pa, pb, cmd" in lse.mapping.objects[0].object
    for c, name in zip(("t", "x", "v", "p1", "p2", "u"), ("time", "pos", "vel", "pa", "pb", "cmd"), strict=True):
        lse.mapping_selects[c].value = name
    lse.mapping_button.clicks += 1
    assert lse.own_data is not None and not lse.mapping.visible
    lse.run()
    np.testing.assert_allclose(lse.result.estimates["M"], estimates["M"], rtol=1e-6)


@pytest.mark.parametrize("content, message", [
    (b"t,x,v,p1,p2,u\n0,0,0,1.2e7,1.8e7,abc\n", "column u, row 1 (line 2): &#x27;abc&#x27; is not a number"),
    (b"t,x,v,p1,p2,u\n" + b"".join(b"%g,0,0,1.2e7,1.8e7,1\n" % (k * 1e-3) for k in range(10)),
     "10 rows of data; need at least 50"),
    (b"t,x,v,p1,p2,u\n" + b"".join(b"%g,0,0,1.2e7,1.8e7,1\n" % (k * 1e-3 + (k > 30) * 5e-4) for k in range(60)),
     "column t, row 32 (line 33): the sampling is not uniform"),
])
def test_malformed_uploads_get_their_message(content, message):
    lse = IdentificationTab(AppState()).lse
    upload(lse, content, "bad.csv")
    assert lse.own_data is None
    assert "your file = &#x27;bad.csv&#x27; is not allowed" in lse.upload_note.object
    assert message in lse.upload_note.object


def test_frequency_downloads():
    from eha_core.data import read_data

    panel = IdentificationTab(AppState()).frequency_panel()
    panel.run()
    for kind in ("csv", "mat"):
        back = read_data(panel.downloads[0 if kind == "csv" else 1].callback().read(), ("t", "r", "x", "u"),
                         filename=f"loop.{kind}")
        np.testing.assert_allclose(back["x"], panel.result.data.x, rtol=1e-9, atol=1e-15)
    est = json.loads(panel.downloads[2].callback().read())
    assert est["estimate"]["den"] == pytest.approx(list(panel.result.estimate.den))
    assert est["settings"]["kp"] == 10.0 and est["validation_fit_percent"] > 90


def test_sensor_noise_changes_the_estimates_reproducibly():
    lse = IdentificationTab(AppState()).lse
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
    lse = IdentificationTab(AppState()).lse
    upload(lse, exported.data_bytes("csv"), "run.csv")
    assert lse.window_form.visible
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


def test_a_transfer_function_from_the_students_own_record():
    source = IdentificationTab(AppState()).frequency_panel()
    source.run()
    record_csv = source.data_bytes("csv")                        # t, r, x, u: the r/x names are understood
    panel = IdentificationTab(AppState()).frequency_panel()
    panel.record_upload.filename = "loop.csv"
    panel.record_upload.value = record_csv
    assert "Your record: loop.csv, 1000 samples every 10 ms" in panel.record_note.object
    panel.run_record()
    rec = panel.record_result
    assert rec.n_estimation == 667 and rec.estimate.fit_percent > 90 and rec.validation.fit_percent > 85
    assert "Validated on the last 333 samples" in panel.record_summary.object
    assert panel.record_view.status == "current" and len(panel.record_bode.points.data["w"]) > 10
    assert "of your record" in panel.record_bode.data_item.label["value"]
    panel.record_detrend.value = "mean"
    assert panel.record_view.status == "stale"
    panel.record_upload.filename = "bad.csv"
    panel.record_upload.value = b"t,u\n0,1\n"
    assert "it needs columns t, u, y (or t, r, x); the file has t, u" in panel.record_note.object
