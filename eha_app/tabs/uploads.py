"""What tab 3's uploads and downloads share: the size limit, the column-mapping step, the download button."""

from __future__ import annotations

import html
import io
from collections.abc import Callable

import panel as pn

__all__ = ["MAX_UPLOAD_BYTES", "check_size", "ColumnMapping", "download"]

#: An upload larger than this is refused (a 10 minute record at 1 kHz is about 2 MB of CSV).
MAX_UPLOAD_BYTES = 20e6


def check_size(data: bytes, filename: str) -> None:
    """Refuse a file larger than :data:`MAX_UPLOAD_BYTES`, naming it and its size."""
    if len(data) > MAX_UPLOAD_BYTES:
        raise ValueError(f"your file = {filename!r} is not allowed: it has {len(data) / 1e6:.1f} MB; "
                         f"at most {MAX_UPLOAD_BYTES / 1e6:g} MB")


class ColumnMapping:
    """Which of the file's columns is each needed one: one select per column, guessed from the
    names (units in brackets ignored), and a button that hands the choice to ``use``.

    ``needed`` maps each needed name to its label and the file names it may go by.
    """

    def __init__(self, needed: dict[str, tuple[str, tuple[str, ...]]], css_prefix: str, *, width: int = 270):
        self.needed = needed
        self.css_prefix = css_prefix
        self.panel = pn.Column(visible=False, width=width, css_classes=[f"eha-{css_prefix}-mapping"])
        self.selects: dict[str, pn.widgets.Select] = {}
        self.button: pn.widgets.Button | None = None

    def ask(self, available: list[str], message: str, use: Callable[[dict], None]) -> None:
        options = ["(none)", *available]
        self.selects = {}
        for c, (label, aliases) in self.needed.items():
            guess = next((a for alias in (c, *aliases) for a in available
                          if a.split("[")[0].strip().lower() == alias), "(none)")
            self.selects[c] = pn.widgets.Select(label=f"{label} is", options=options, value=guess, width=250,
                                                css_classes=[f"eha-map-{c}"])
        self.button = pn.widgets.Button(label="Use these columns", color="primary", width=250,
                                        css_classes=["eha-map-go"])
        self.button.on_click(lambda _e: use({c: s.value for c, s in self.selects.items() if s.value != "(none)"}))
        self.panel.objects = [pn.pane.HTML(f"<span class='eha-warn'>{html.escape(message)}</span>"),
                              *self.selects.values(), self.button]
        self.panel.visible = True

    def hide(self) -> None:
        self.panel.visible = False


def download(make: Callable[[], bytes], filename: str, label: str, css_class: str, *, width: int = 128,
             description: str | None = None) -> pn.widgets.FileDownload:
    """A download button, disabled until its tab has something to offer; ``make()`` writes the
    file's bytes when it is pressed (on the session's thread: the files are small)."""
    extra = {"description": description} if description else {}
    return pn.widgets.FileDownload(callback=lambda: io.BytesIO(make()), filename=filename, label=label,
                                   disabled=True, width=width, css_classes=[css_class], **extra)
