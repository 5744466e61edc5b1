import ast
import subprocess
import sys
from pathlib import Path

import pytest

CORE = Path(__file__).resolve().parents[2] / "eha_core"
#: Never imported by the core, at module level or inside a function.
FORBIDDEN = ("eha_app", "panel", "bokeh", "holoviews", "param")


def imported_names(path: Path) -> list[tuple[int, str]]:
    """Every module an import statement names in ``path``, lazy ones included."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.append((node.lineno, node.module))
        elif isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", "")) in (
                "import_module", "__import__") and node.args and isinstance(node.args[0], ast.Constant):
            names.append((node.lineno, str(node.args[0].value)))
    return names


def test_the_core_imports_nothing_from_the_app_or_the_gui():
    modules = sorted(CORE.rglob("*.py"))
    assert len(modules) > 15
    offending = [f"{p.relative_to(CORE.parent)}:{line} imports {name}"
                 for p in modules for line, name in imported_names(p)
                 if name.split(".")[0] in FORBIDDEN]
    assert not offending, offending


@pytest.mark.parametrize("module", ["eha_core", "eha_core.params", "eha_core.simulate", "eha_core.linear",
                                    "eha_core.experiments", "eha_core.signals", "eha_core.excitation",
                                    "eha_core.data", "eha_app.cli"])
def test_core_and_command_line_imports_stay_light(module):
    """Cold start: no GUI stack, and control and numba deferred (``eha --help`` is quick)."""
    code = (f"import sys, {module}; "
            "print(' '.join(m for m in ('panel', 'holoviews', 'bokeh', 'control', 'numba', 'matplotlib', 'scipy') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True)
    assert out.stdout.strip() == ""
