"""A regular (non-editable) install carries everything the app needs at run time."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_a_wheel_install_carries_the_schematic(tmp_path):
    # from a clean copy of the sources: a checkout's build/ and egg-info would
    # supply files the package's own configuration forgets
    src, dist, site = tmp_path / "src", tmp_path / "dist", tmp_path / "site"
    skip = shutil.ignore_patterns(".git", ".venv", "build", "*.egg-info", "__pycache__", ".pytest_cache")

    def ignore(folder, names):
        top = {"assets", "tests", "benchmarks"} if Path(folder) == ROOT else set()   # the README's pictures etc.
        return set(skip(folder, names)) | (top & set(names))

    shutil.copytree(ROOT, src, ignore=ignore)
    subprocess.run([sys.executable, "-m", "pip", "wheel", str(src), "--no-deps", "-q",
                    "-w", str(dist)], check=True, capture_output=True, timeout=300)
    wheel = next(dist.glob("eha-*.whl"))
    subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(site), str(wheel)],
                   check=True, capture_output=True, timeout=300)
    code = (
        "import eha_app, eha_core; "
        "from eha_app.app import create_app; "
        "page = create_app(); tab = page.session.section(\"parameters\"); "
        "panel = tab.__panel__(); "
        "html = ' '.join(str(getattr(o, 'object', '')) for o in panel.select()); "
        "print(eha_app.__file__); print(eha_core.__file__); print('<svg' in html)")
    # run from elsewhere, with the installed copy first on the path
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=300,
                         env={"PYTHONPATH": str(site), "PATH": "/usr/bin:/bin"})
    assert out.returncode == 0, out.stderr[-2000:]
    app_file, core_file, has_svg = out.stdout.split()[-3:]
    assert app_file.startswith(str(site)) and core_file.startswith(str(site))
    assert has_svg == "True"
