"""The app's layers, checked rather than reviewed: each imports only the layers below it.

    eha_core                         numbers and typed results (never the app)
    eha_app.runtime                  serving, the queue, the page's lock, limits, patches, hand-ins
    eha_app.render                   figures, tables, reports and files drawn from core results
    eha_app.session                  a page's session, its state, its forms, the section protocol
    eha_app.sections                 the tabs and panels (registered in eha_app/sections/__init__.py)
    eha_app.app, eha_app.eha         the page: the sections' tabs, the gate of an exercise
    eha_app.guide                    the page: the start card and the guide line through the steps
    eha_app.dashboard, .teacher      the teacher's page of an exercise (at /teacher)
    eha_app.cli                      the ``eha`` command: an interface beside the page

Every import counts, lazy ones inside functions included.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
APP = ROOT / "eha_app"

#: What each layer may import, besides itself, the standard library and third-party packages.
ALLOWED = {
    "runtime": {"eha_core"},
    "render": {"eha_core", "runtime"},
    "session": {"eha_core", "runtime", "render"},
    "sections": {"eha_core", "runtime", "render", "session"},
    "app": {"eha_core", "runtime", "render", "session", "sections"},
    "cli": {"eha_core", "runtime", "render", "session", "sections", "app"},
}


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def layer_of(module: str) -> str | None:
    """``eha_app.render.plots`` -> ``render``; ``eha_core...`` -> ``eha_core``; others: None."""
    parts = module.split(".")
    if parts[0] == "eha_core":
        return "eha_core"
    if parts[0] != "eha_app":
        return None
    if len(parts) == 1:
        return "app"
    return {"eha": "app", "app": "app", "guide": "app", "dashboard": "app", "teacher": "app"}.get(parts[1], parts[1])


def imports_of(path: Path) -> list[tuple[int, str]]:
    """Every module ``path`` imports (relative ones resolved), lazy ones included."""
    module = module_name(path)
    package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            out.append((node.lineno, target))
            # "from . import plots": the names may be modules of their own
            out += [(node.lineno, f"{target}.{a.name}") for a in node.names
                    if (ROOT / (target.replace(".", "/") + f"/{a.name}.py")).exists()
                    or (ROOT / (target.replace(".", "/") + f"/{a.name}")).is_dir()]
    return out


def violations() -> list[str]:
    found = []
    for path in sorted(APP.rglob("*.py")):
        own = layer_of(module_name(path))
        for line, name in imports_of(path):
            other = layer_of(name)
            if other is None or other == own:
                continue
            if other not in ALLOWED[own]:
                found.append(f"{path.relative_to(ROOT)}:{line} ({own}) imports {name} ({other})")
    return found


def test_every_module_of_the_app_is_in_a_layer():
    layers = {layer_of(module_name(p)) for p in APP.rglob("*.py")}
    assert layers == set(ALLOWED), layers


def test_each_layer_imports_only_the_layers_below_it():
    assert violations() == []


def test_the_check_finds_an_import_upwards(tmp_path, monkeypatch):
    """The checker itself: a render module that imports a section is caught."""
    fake = APP / "render" / "_layer_probe.py"
    fake.write_text("def f():\n    from ..sections import board\n    return board\n", encoding="utf-8")
    try:
        found = violations()
    finally:
        fake.unlink()
    assert found == ["eha_app/render/_layer_probe.py:2 (render) imports eha_app.sections (sections)",
                     "eha_app/render/_layer_probe.py:2 (render) imports eha_app.sections.board (sections)"]
