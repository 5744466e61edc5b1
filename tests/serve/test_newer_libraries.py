"""The app on a Panel and Bokeh newer than its patches were written for: they are not applied, the
server says which in one line each, and a student's page still works (eha_app/runtime/patches.py).

The server runs with ``importlib.metadata.version`` answering Panel 1.10.0 and Bokeh 3.10.0 (the
installed libraries' code is unchanged: only the versions the patches check are faked).
"""

from __future__ import annotations

import asyncio
import subprocess
import sys

from benchmarks.classroom_client import Student, stop_server

from .conftest import ROOT, free_port, wait_http

FAKE = """
import importlib.metadata as metadata, sys
import bokeh, panel     # their own version strings (resource URLs, hashes) stay the installed ones
real = metadata.version
metadata.version = lambda name: {"bokeh": "3.10.0", "panel": "1.10.0"}.get(name) or real(name)
from eha_app.cli import main
sys.exit(main(sys.argv[1:]))
"""


def test_a_newer_panel_and_bokeh_serve_the_page_without_the_patches(tmp_path, monkeypatch):
    monkeypatch.setenv("EHA_STRICT", "1")       # asked for, but it cannot be checked on another Bokeh
    port = free_port()
    log_path = tmp_path / "serve.log"
    with open(log_path, "w") as log:
        proc = subprocess.Popen([sys.executable, "-c", FAKE, "serve", "--port", str(port), "--address", "127.0.0.1",
                                 "--workers", "1"], cwd=ROOT, stdout=log, stderr=subprocess.STDOUT,
                                start_new_session=True)
        try:
            url = f"http://127.0.0.1:{port}/eha"
            wait_http(url, proc)

            async def scenario():
                s = Student(url, name="newer", timeout=60)
                await s.open()
                await s.change_parameter("M", "7000", timeout=30)
                await s.show_simulation()
                await s.compare_both()
                await s.show_identification()
                await s.least_squares()
                await s.show_frequency()
                await s.frequency_experiment()
                await s.show_tab(0, s.FORM)
                await s.change_parameter("M", "5000", timeout=30)
                # (Panel names the component's model ConnectionWatch1, ...)
                watch = s.find(where=lambda m: m.type.startswith("ConnectionWatch"))
                ready_js = [m for m in s.find("CustomJS", live=False)
                            if "ehaControlsBeforeRender" in str(m.attributes.get("code"))]
                await s.close()
                return watch, ready_js

            watch, ready_js = asyncio.run(scenario())
        finally:
            stop_server(proc)
    text = log_path.read_text(errors="replace")
    # every patch written for Bokeh 3.9 or Panel 1.9 said it is not applied, in one line each
    from eha_app.runtime.patches import PATCHES

    versioned = [n for n, p in PATCHES.items() if p.library in ("bokeh", "panel") and p.versions is not None
                 and n != "shared_port"]
    for name in versioned:
        assert text.count(f"library patch {name} not applied: ") == 1, (name, text[-3000:])
    summary = [line for line in text.splitlines() if line.startswith("eha serve: library patches applied:")]
    assert len(summary) == 1
    applied = summary[0].split("applied: ", 1)[1].split(";")[0].split(", ")
    # the security guards (on public Tornado hooks) stay, the Python-only ones too; nothing written
    # for Bokeh 3.9 or Panel 1.9
    assert {"component_guard", "teacher_routes"} <= set(applied) and not set(applied) & set(versioned)
    # the page's BokehJS is not patched either
    assert watch and all(not w.get("install") for w in watch), [w.get("install") for w in watch]  # unset: []
    assert ready_js == []
    assert "Traceback" not in text and " ERROR" not in text, text[-3000:]


def test_several_processes_are_refused_at_once_without_the_shared_port():
    """--num-procs 2 needs the shared_port patch: on a Bokeh it was not written for, eha serve says so
    in one line and exits 2 before it starts anything (no process restarted again and again)."""
    done = subprocess.run([sys.executable, "-c", FAKE, "serve", "--port", str(free_port()), "--num-procs", "2"],
                          cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert done.returncode == 2, done.stderr[-2000:]
    assert done.stderr.strip().splitlines()[-1] == (
        "eha serve: --num-procs above 1 needs the shared_port patch (bokeh 3.10.0 is not the 3.9 it was written "
        "for): serve with --num-procs 1, or install bokeh 3.9")
    assert "Starting the server" not in done.stdout
