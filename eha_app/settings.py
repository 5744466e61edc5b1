"""A session's settings as a JSON file: every input of every tab, saved and loaded again.

The file holds the texts as typed (display units), by tab; loading one types
them in, so a bad value gets the same message as a bad value typed, and the
results follow (tab 2 re-runs; tab 3's results are marked out of date). An
exercise's hidden parameters are neither saved nor loaded.
"""

from __future__ import annotations

import json

from eha_core.params import PARAM_NAMES

from .state import shown_text, too_long

__all__ = ["FORMAT", "MAX_SETTINGS_BYTES", "collect", "apply", "SettingsError"]

FORMAT = "eha-settings/1"
#: A settings file is about 2 kB; a larger one is refused before it is read (in the page, before
#: it is even sent), so that no file can hold the server's thread or fill its log.
MAX_SETTINGS_BYTES = 100_000
_SECTIONS = ("parameters", "simulation", "least_squares", "frequency", "board", "study")


class SettingsError(ValueError):
    """A settings file that cannot be loaded, with what is wrong."""


def _defaults():
    from .tabs.board import BOARD_DEFAULTS
    from .tabs.identification import FREQ_DEFAULTS, LSE_DEFAULTS
    from .tabs.simulation import DEFAULT_TEXTS
    from .tabs.study import STUDY_DEFAULTS

    return {"simulation": DEFAULT_TEXTS, "least_squares": LSE_DEFAULTS, "frequency": FREQ_DEFAULTS,
            "board": BOARD_DEFAULTS, "study": STUDY_DEFAULTS}


def _tabs(page):
    built = page.eha_lazy.built
    sim = built.get(1)
    ident = built.get(2)
    return {"simulation": sim.form if sim is not None else None,
            "least_squares": ident.lse.form if ident is not None else None,
            "frequency": ident.freq.form if ident is not None and ident.freq is not None else None,
            "board": ident.board.form if ident is not None and ident.board is not None else None,
            "study": ident.study.form if ident is not None and ident.study is not None else None}


def collect(page) -> dict:
    """Every input of the session (texts as typed), as the settings file holds them."""
    state = page.eha_state
    out = {"format": FORMAT,
           "parameters": {**{n: state.texts[n] for n in PARAM_NAMES if n not in state.hidden}, "kp": state.kp_text},
           "tab": int(page.eha_tabs.active) + 1}
    forms = _tabs(page)
    for section, defaults in _defaults().items():
        form = forms[section]
        values = dict(form.values) if form is not None else {k: page.eha_query.get(k, v) for k, v in defaults.items()}
        out[section] = {k: str(v) for k, v in values.items() if k in defaults}
    return out


def to_bytes(page) -> bytes:
    return json.dumps(collect(page), indent=1, ensure_ascii=False).encode()


def apply(page, data: bytes | str, filename: str = "settings.json") -> list[str]:
    """Type a settings file's values into the session; returns notes (fields it does not know)."""
    if len(data) > MAX_SETTINGS_BYTES:
        raise SettingsError(f"settings = {filename!r} is not allowed: it has {len(data) / 1e3:.1f} kB; at most "
                            f"{MAX_SETTINGS_BYTES / 1e3:g} kB (a saved settings file has about 2 kB)")
    try:
        doc = json.loads(data)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise SettingsError(f"settings = {filename!r} is not allowed: it is not JSON ({exc})") from None
    except RecursionError:
        raise SettingsError(f"settings = {filename!r} is not allowed: it is nested too deeply to be a settings "
                            "file; save one with “Save settings”") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise SettingsError(f"settings = {filename!r} is not allowed: not a settings file of this app "
                            f"(format {FORMAT!r} expected); save one with “Save settings”")
    notes = []
    unknown = [k for k in doc if k not in (*_SECTIONS, "format", "tab")]
    state = page.eha_state
    params = _section(doc, "parameters", filename)
    for name, text in params.items():
        if name in state.hidden:
            continue
        if name in PARAM_NAMES or name == "kp":
            state.set_text(name, text)
        else:
            unknown.append(f"parameters.{name}")
    tab1 = page.eha_lazy.built.get(0)
    if tab1 is not None:
        tab1.form.values = tab1._texts()
    forms = _tabs(page)
    for section, defaults in _defaults().items():
        given = _section(doc, section, filename)
        values = {k: v for k, v in given.items() if k in defaults}
        unknown += [f"{section}.{k}" for k in given if k not in defaults]
        form = forms[section]
        if form is not None:
            form.set_values(**values)
        else:                   # the tab is built later, from the page's query
            page.eha_query.update(values)
    if unknown:
        shown = ", ".join(shown_text(u, 40) for u in unknown[:10]) + (f" and {len(unknown) - 10} more"
                                                                       if len(unknown) > 10 else "")
        notes.append(f"settings = {filename!r}: ignored what this app does not know: {shown}")
    return notes


def _section(doc: dict, section: str, filename: str) -> dict[str, str]:
    """A section of the file as ``{field: text}``: texts (or numbers), each a field's worth."""
    given = doc.get(section) or {}
    if not isinstance(given, dict):
        raise SettingsError(f"settings = {filename!r} is not allowed: its {section!r} is not a list of fields")
    out = {}
    for name, value in given.items():
        if isinstance(value, bool) or not isinstance(value, (str, int, float)):
            raise SettingsError(f"settings = {filename!r} is not allowed: {section}.{shown_text(name, 40)} is not "
                                "a text or a number")
        text = str(value)
        if too_long(text):
            raise SettingsError(f"settings = {filename!r} is not allowed: {section}.{shown_text(name, 40)} = "
                                f"{shown_text(text)}: {too_long(text)}")
        out[str(name)] = text
    return out
