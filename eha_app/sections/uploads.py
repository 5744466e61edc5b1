"""What the page's uploads and tab 3's downloads share: the upload widget and its size limit, the
column-mapping step, the download button."""

from __future__ import annotations

import html
import io
from collections.abc import Callable

import panel as pn
import param
from panel.custom import JSComponent

from eha_core.data import MAX_DATA_BYTES
from eha_core.errors import FieldError

from ..runtime.tasks import on_click

__all__ = ["MAX_UPLOAD_BYTES", "kept_upload", "read_kept", "FileUpload", "check_size", "upload_name",
           "ColumnMapping", "download", "known_on_file", "file_source"]

#: An upload larger than this is refused, in the page before it is sent and by the server
#: (the same limit as the data reader's; the server's websocket takes a file this size).
MAX_UPLOAD_BYTES = MAX_DATA_BYTES


def _too_big(filename: str, size: int, limit: int) -> str:
    return str(FieldError("your file", filename, f"it has {size / 1e6:.1f} MB; at most {limit / 1e6:g} MB",
                          value_text=repr(filename)))


#: The same sentence, written by the browser before it sends a file (a JavaScript template).
_TOO_BIG_JS = str(FieldError("your file", None, "it has ${(file.size / 1e6).toFixed(1)} MB; at most "
                             "${model.max_bytes / 1e6} MB", value_text="'${file.name}'"))


def known_on_file(state, estimated=()):
    """The parameters a route takes as known on an uploaded file, and the sentence that says which
    hidden ones are at the paper's value: ``(params, note_html)``, the note "" outside an exercise
    (see :meth:`~eha_app.session.state.AppState.known_params`). ``estimated``: those the route
    estimates (their values are guesses or not used, so not named). Raises ``ParameterError``
    with a sentence for the page when the paper's values do not fit what the student typed."""
    from eha_core.param_table import FIELD_INFO
    from eha_core.params import ActuatorParams, ParameterError

    from ..render.tables import SYMBOLS_HTML

    if not state.hidden:
        return state.params, ""
    try:
        params = state.known_params()
    except ParameterError as exc:
        raise ParameterError(exc.field, exc.value, "on a file, the hidden parameters are taken at the paper's "
                             f"values, and with them {exc.allowed}; type values that fit the paper's") from None
    paper = ActuatorParams()
    named = [n for n in state.hidden if n not in estimated]
    if not named:
        return params, ""
    values = ", ".join(f"{SYMBOLS_HTML.get(n, html.escape(n))} = {getattr(paper, n) / FIELD_INFO[n].display_scale:.4g}"
                       f" {html.escape(FIELD_INFO[n].display_unit)}" for n in named)
    return params, (f"<p class='eha-note eha-paper-values'>Your file is not your actuator's experiment: the hidden "
                    f"{values} {'is' if len(named) == 1 else 'are'} taken at the paper's value"
                    f"{'' if len(named) == 1 else 's'}, not your actuator's.</p>")


def kept_upload(key: str, upload, own_data, own_data_key):
    """The file section ``key`` ran its result on, as an exercise keeps it for a student who joins
    again (a :class:`~eha_app.runtime.work_store.StoredFile` with its column mapping), or None when it
    ran on the simulated sensors. ``upload``: the file as given, ``(bytes, name)``; ``own_data`` and
    ``own_data_key``: what was read of it, and under which ``(name, size, mapping)``."""
    from ..runtime.work_store import StoredFile

    if own_data is None or upload is None:
        return None
    data, name = upload
    mapping = dict(own_data_key[2]) if own_data_key and own_data_key[2] else None
    return StoredFile(key, name, data, mapping)


def read_kept(upload):
    """The restore step that gives a section back the file it kept (``upload``, a
    :class:`~eha_app.runtime.work_store.StoredFile`): its ``use_file``, with the kept column mapping."""
    from ..session import RestoreStep

    return RestoreStep("", lambda section: section.use_file(upload.data, upload.name, upload.mapping))


def file_source(name: str, data: bytes) -> dict:
    """What a hand-in records of an uploaded file it came from: its name and the start of its SHA-256
    (two students handing in from one file show the same digest on the teacher's dashboard)."""
    import hashlib

    return {"kind": "file", "name": str(name), "sha256": hashlib.sha256(data).hexdigest()[:16]}


def upload_name(filename: str | None) -> str:
    """An upload's name as the page shows and exports it: the page sends it, so it is bounded here."""
    from ..session.state import shown_text

    return shown_text(filename or "upload", 80)


def check_size(data: bytes, filename: str, limit: int = MAX_UPLOAD_BYTES) -> None:
    """Refuse a file larger than ``limit``, naming it and its size."""
    if len(data) > limit:
        raise ValueError(_too_big(filename, len(data), limit))


class FileUpload(JSComponent):
    """A file chooser that refuses a file over ``max_bytes`` in the page, before sending a byte of it.

    Bokeh's own ``FileInput`` sends any file, base64-encoded in one websocket
    message: a 19 MB file went past the server's message limit and the
    connection closed, taking the student's session with it. Here the browser
    checks the size first and says what is allowed beside the chooser; a file
    within the limit goes to the server as raw bytes, with its name
    (``filename`` and ``value`` change in one message).
    """

    accept = param.String(default="", doc="file types offered, e.g. '.csv,.mat'")
    label = param.String(default="", doc="""
        The chooser's name, e.g. 'Load settings (a JSON file)': a file input has no visible label of
        its own (its button says 'Choose file'), and a screen reader would announce it unnamed.""")
    max_bytes = param.Integer(default=MAX_UPLOAD_BYTES, bounds=(1, None), doc="the largest file sent")
    filename = param.String(default=None, allow_None=True, doc="the name of the last file sent")
    value = param.Bytes(default=None, allow_None=True, doc="the last file's bytes")

    _stylesheets = ["""
:host { display: block; }
input[type=file] { font: inherit; font-size: 13px; max-width: 100%; padding: 3px;
                   border: 1px solid #c3c9d3; border-radius: 4px; background: #fff; box-sizing: border-box; }
.eha-upload-refused { color: #b00020; font-size: 12px; margin-top: 2px; }
.eha-upload-refused:empty { display: none; }
"""]

    _esm = """
export function render({ model, el }) {
  const input = document.createElement('input')
  input.type = 'file'
  input.accept = model.accept || ''
  if (model.label) { input.setAttribute('aria-label', model.label) }
  const refused = document.createElement('div')
  refused.className = 'eha-upload-refused'
  refused.setAttribute('role', 'alert')
  input.addEventListener('change', async () => {
    const file = input.files.length ? input.files[0] : null
    if (file === null) { return }
    if (file.size > model.max_bytes) {
      refused.textContent = `__TOO_BIG__`
      input.value = ''
      return
    }
    refused.textContent = ''
    const bytes = await file.arrayBuffer()
    model.data.setv({ filename: file.name, value: bytes })
  })
  el.append(input, refused)
}
""".replace("__TOO_BIG__", _TOO_BIG_JS)


class ColumnMapping:
    """Which of the file's columns is each needed one: one select per column, guessed from the
    names (units in brackets ignored), and a button that hands the choice to ``use``.

    ``needed`` maps each needed name to its label and the file names it may go by; ``if_missing``, a
    needed name to what the question adds when the file seems not to have it (HTML: e.g. where else a
    file without it can go).
    """

    def __init__(self, needed: dict[str, tuple[str, tuple[str, ...]]], css_prefix: str, *, width: int = 270,
                 if_missing: dict[str, str] | None = None):
        self.needed = needed
        self.if_missing = dict(if_missing or {})
        self.css_prefix = css_prefix
        self.panel = pn.Column(visible=False, width=width, css_classes=[f"eha-{css_prefix}-mapping"])
        self.selects: dict[str, pn.widgets.Select] = {}
        self.button: pn.widgets.Button | None = None

    def ask(self, available: list[str], filename: str, use: Callable[[dict], None]) -> None:
        """Show the file's columns with a guess for each needed one (names, then units) for the student
        to check: a file waiting for its columns is a question, not an error."""
        from eha_core.data import columns_text, guess_columns

        options = ["(none)", *available]
        guesses = guess_columns(available, list(self.needed), {c: a for c, (_, a) in self.needed.items()})
        self.selects = {}
        for c, (label, _aliases) in self.needed.items():
            self.selects[c] = pn.widgets.Select(label=f"{label} is", options=options, value=guesses[c] or "(none)",
                                                width=250, css_classes=[f"eha-map-{c}"])
        self.button = pn.widgets.Button(label="Use these columns", color="primary", width=250,
                                        css_classes=["eha-map-go"])
        on_click(self.button, lambda _e: use({c: s.value for c, s in self.selects.items() if s.value != "(none)"}))
        found = [c for c, g in guesses.items() if g]
        missing = [self.needed[c][0] for c, g in guesses.items() if not g]
        guessed = ("All guessed from the names and units: check them" if not missing else
                   (f"Guessed {len(found)} of {len(guesses)} from the names and units; choose "
                    f"{', '.join(missing)}") if found else "Choose which column is which")
        self.panel.objects = [pn.pane.HTML(
            f"<div class='eha-map-question'><b>Which columns of {html.escape(filename)} are which?</b> "
            f"It has {html.escape(columns_text(available))}, not all named {', '.join(self.needed)}. {guessed}, "
            "then press “Use these columns”. "
            "Units in brackets are converted (position[mm], pA[bar])."
            + "".join(f" {self.if_missing[c]}" for c, g in guesses.items() if not g and c in self.if_missing)
            + "</div>", css_classes=["eha-map-note"]),
            *self.selects.values(), self.button]
        self.panel.visible = True

    @property
    def waiting(self) -> bool:
        """Whether a file waits for the student to say which columns are which."""
        return self.panel.visible

    def hide(self) -> None:
        self.panel.visible = False


def download(make: Callable[[], bytes], filename: str, label: str, css_class: str, *, width: int = 128,
             description: str | None = None) -> pn.widgets.FileDownload:
    """A download button, disabled until its tab has something to offer; ``make()`` writes the
    file's bytes when it is pressed (on the session's thread: the files are small)."""
    extra = {"description": description} if description else {}
    return pn.widgets.FileDownload(callback=lambda: io.BytesIO(make()), filename=filename, label=label,
                                   disabled=True, width=width, css_classes=[css_class], **extra)
