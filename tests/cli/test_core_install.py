"""The core installs alone: `pip install .` without extras gives a working `eha simulate` and
`import eha_core`, without the web app's libraries (they are the `app` extra), and the commands that
need the app say so in one line."""

from __future__ import annotations

import shutil
import subprocess
import sys
import venv
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[2]
#: What a source distribution of the project holds (the working tree's, as a user would install it).
SOURCES = ("pyproject.toml", "README.md", "LICENSE", "eha_core", "eha_app")


@pytest.fixture(scope="module")
def core_env(tmp_path_factory):
    """A fresh virtual environment with the project installed without extras (about 25 s from pip's
    cache; the wheels come from the package index otherwise)."""
    base = tmp_path_factory.mktemp("core")
    src = base / "src"
    src.mkdir()
    for name in SOURCES:
        path = ROOT / name
        if path.is_dir():
            shutil.copytree(path, src / name, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        else:
            shutil.copy2(path, src / name)
    env = base / "venv"
    venv.create(env, with_pip=True)
    bin_dir = env / ("Scripts" if sys.platform == "win32" else "bin")
    out = subprocess.run([str(bin_dir / "python"), "-m", "pip", "install", "-q", "--disable-pip-version-check",
                          str(src)], capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr[-2000:]
    return bin_dir, base


def _run(bin_dir, *args, cwd=None, timeout=600):
    return subprocess.run([str(bin_dir / args[0]), *args[1:]], capture_output=True, text=True, cwd=cwd,
                          timeout=timeout)


def test_the_core_installs_without_the_web_app_and_simulates(core_env):
    bin_dir, base = core_env
    listed = _run(bin_dir, "python", "-m", "pip", "list", "--format=freeze", "--disable-pip-version-check")
    installed = {line.split("==")[0].lower() for line in listed.stdout.splitlines() if "==" in line}
    assert not installed & {"panel", "bokeh", "holoviews", "threadpoolctl", "tornado"}, installed
    assert {"numpy", "scipy", "numba", "pandas", "control"} <= installed
    ok = _run(bin_dir, "python", "-c", "import eha_core, eha_core.identify.greybox; print('ok')")
    assert ok.returncode == 0 and ok.stdout.strip() == "ok", ok.stderr
    sim = _run(bin_dir, "eha", "simulate", "--case", "1", "--t-end", "0.2", "--out", str(base / "run.csv"))
    assert sim.returncode == 0, sim.stderr
    rows = (base / "run.csv").read_text().splitlines()
    assert rows[0].startswith("t,x,v,p1,p2") and len(rows) > 100
    assert _run(bin_dir, "eha", "--version").stdout.startswith("eha ")


def test_the_commands_that_need_the_app_say_how_to_install_it(core_env):
    bin_dir, _ = core_env
    for command in (("eha", "serve"), ("eha", "reproduce", "--out", "rep")):
        out = _run(bin_dir, *command)
        lines = out.stderr.strip().splitlines()
        assert out.returncode == 2 and len(lines) == 1 and "Traceback" not in out.stderr, out.stderr
        assert 'pip install "eha[app]"' in lines[0]
