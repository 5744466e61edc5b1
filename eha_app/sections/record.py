"""Tab 3, frequency domain: a transfer function from the student's own record.

The student uploads t, u, y (or the closed loop's t, r, x) as CSV or .mat,
maps the columns when the names differ, chooses the part of the record and
whether to remove its mean or a linear trend (drawn on the record's plot as it
is chosen), and estimates H(s) on the first two thirds, validated on the rest.
"""

from __future__ import annotations

import html
from functools import partial

import numpy as np
import panel as pn

from eha_core.board import BoardModel

from ..render import plots
from ..render.exports import bode_csv, tf_estimate_bytes
from ..render.formatting import tf_html
from ..render.glossary import term
from ..render.tables import estimate_alert, estimation_sentences
from ..runtime.tasks import apply_locked, on_click, watch
from ..runtime.work_store import StoredFile
from ..session import KeptWork, ReportPart, RestoreStep, Section, SectionSnapshot, stale_note
from ..session.form import Field, Form, Group
from ..session.freshness import ResultView
from .uploads import ColumnMapping, FileUpload, check_size, download, read_kept, upload_name

__all__ = ["RecordPanel", "RECORD_COLUMNS"]

#: The columns a record needs, with the closed loop's names they may go by (u = r, y = x).
RECORD_COLUMNS = {"t": ("t", ()), "u": ("input u (or r)", ("r",)), "y": ("output y (or x)", ("x",))}
DETRENDS = {"nothing": "none", "the mean": "mean", "a linear trend": "linear"}
_WINDOW_FIELDS = ("rec_from", "rec_to")
#: The section's inputs besides the file: the part of the record and what is removed from it.
RECORD_DEFAULTS = {"rec_from": "", "rec_to": "", "rec_detrend": "none"}


class RecordPanel(Section):
    """The own-record part of the frequency-domain panel (a section within it).

    The frequency panel gives the model settings (poles, zeros, initial
    condition, input offset, delay: its ``config()``, None while they are not
    valid), its queue note and its alert.
    """

    key = "record"
    title = "Your own record"
    defaults = RECORD_DEFAULTS
    #: its range (the detrend is a select beside it); shown once a record is read
    form_css = "eha-freq-record-window"
    run_buttons = ("Estimate from your record",)

    def __init__(self, session, **kwargs):
        super().__init__(session, **kwargs)
        runner = self.runner
        parent = session.section(session.registry.get(self.key).within)
        # previews of the preprocessing are jobs of their own: they must not replace an estimate
        self.preview_runner = runner.sub("record preview")
        # the form's model settings; None while any field of the form is refused (a parse error, or an
        # excitation idinput refused: the form shows it, and every run of the panel waits for it)
        self.orders = lambda: None if parent.excitation_errors else parent.config()[0]
        self._note, self._fail = parent.queue_note_text, parent.fail
        texts = self.initial_texts()
        self.columns: tuple[np.ndarray, np.ndarray, np.ndarray, str] | None = None    # t, u, y, file name
        self._uploads = 0
        self._upload: tuple[bytes, str] | None = None
        self._mapping: dict | None = None
        self.prepared = None
        self.result = None
        self.note = pn.pane.HTML(
            "<span class='eha-note'>Or estimate H(s) from your own record: a CSV or .mat file with t, u, y "
            "(or t, r, x), in SI or with units in the header. Its first two thirds estimate, the rest "
            "validates; the model's poles, zeros, initial condition, offset and delay are the form's.</span>",
            width=270, css_classes=["eha-freq-record-note"])
        self.upload = FileUpload(accept=".csv,.mat", width=260, css_classes=["eha-freq-upload"],
                                 label="Your own record (a CSV or .mat file)")
        watch(self.upload, self._uploaded, "value")
        self.mapping = ColumnMapping(RECORD_COLUMNS, "freq-record")
        self.window_form = Form(spec=[Group("Part of your record to use", (
            Field("rec_from", "from t", "text", unit="s", placeholder="its start", short="from t"),
            Field("rec_to", "to t", "text", unit="s", placeholder="its end", short="to t"),
        )).to_spec()], values={k: texts[k] for k in _WINDOW_FIELDS}, width=270, visible=False,
            css_classes=[self.form_css], margin=(5, 10))
        detrend = texts["rec_detrend"] if texts["rec_detrend"] in DETRENDS.values() else "none"
        self.detrend = pn.widgets.Select(label="remove from u and y", value=detrend, width=260,
                                         options=DETRENDS, visible=False, css_classes=["eha-freq-record-detrend"])
        self.button = pn.widgets.Button(label="Estimate from your record", disabled=True, width=260,
                                        css_classes=["eha-freq-record-run"])
        on_click(self.button, lambda _e: self.run())
        self.data_figure: plots.RecordDataFigure | None = None
        self.data_area = pn.Column(sizing_mode="stretch_width", visible=False, css_classes=["eha-freq-record-data"])
        self.summary = pn.pane.HTML("", sizing_mode="stretch_width", css_classes=["eha-freq-record-summary"])
        self.bode: plots.BodeFigure | None = None
        self.area = pn.Column(self.summary, sizing_mode="stretch_width", visible=False)
        self.view = ResultView("freq-record", self.area, run_hint="Press “Estimate from your record” to update it.")
        self.downloads = [
            download(lambda: self.estimate_bytes("csv"), "eha_record_transfer_function.csv",
                     "Estimate (CSV)", "eha-dl-record-csv"),
            download(lambda: self.estimate_bytes("json"), "eha_record_transfer_function.json",
                     "Estimate (JSON)", "eha-dl-record-json"),
            download(lambda: bode_csv(self.result.bode, theoretical=False), "eha_record_bode.csv",
                     "Bode curves (CSV)", "eha-dl-record-bode", width=260),
        ]
        # shown through a box: the form's own "visible" did not hide it when the page first drew it
        self.window_box = pn.Column(self.window_form, visible=False, margin=0)
        watch(self.window_form, lambda _e: self.preview(), "values")
        watch(self.detrend, lambda _e: self.preview(), "value")

    # -- inputs ------------------------------------------------------------------------------
    def window(self) -> tuple[str, str]:
        return tuple(str(self.window_form.values.get(k, "")).strip() for k in _WINDOW_FIELDS)

    def run_key(self):
        """What an estimate from the record is computed from (None: no record, or invalid settings)."""
        cfg = self.orders()
        if self.columns is None or cfg is None or self.window_form.errors:
            return None
        return (self._uploads, self.columns[3], self.columns[0].size, self.window(), self.detrend.value, cfg.n_poles,
                cfg.n_zeros, cfg.initial_condition, cfg.input_offset, cfg.input_delay)

    def inputs_changed(self) -> None:
        self.view.inputs_changed(self.run_key())
        # a file waiting for its columns: the button would estimate from the previous record
        self.button.disabled = self.run_key() is None or self.mapping.waiting

    # -- reading the file ----------------------------------------------------------------------
    def _uploaded(self, _event) -> None:
        if self.upload.value is None:
            return
        self._upload = (bytes(self.upload.value), upload_name(self.upload.filename))
        self.read(None)

    def use_file(self, data: bytes, filename: str, mapping: dict | None = None):
        """Use ``data`` (a file named ``filename``) as the student's record, its columns read with ``mapping``
        (None: by their names); returns the job that reads it."""
        self._upload = (data, filename)
        return self.read(mapping)

    def read(self, mapping: dict | None):
        """Read the upload in a worker: its t, u, y (or t, r, x, or the mapped columns), or ask for a mapping."""
        from eha_core.data import DataError, columns_text, file_columns, read_data, sample_time

        if self._upload is None:
            return
        data, filename = self._upload

        def columns(needed):
            return read_data(data, needed, name="your file", filename=filename, mapping=mapping, min_rows=20)

        def compute(_token):
            check_size(data, filename)
            try:
                cols = columns(("t", "u", "y"))
                u, y = cols["u"], cols["y"]
            except DataError as exc:
                if not exc.missing_columns or mapping:
                    raise
                try:
                    cols = columns(("t", "r", "x"))
                    u, y = cols["r"], cols["x"]
                except DataError as second:
                    if not second.missing_columns:
                        raise
                    have = columns_text(exc.file_columns)
                    message = f"your file {filename}: it needs columns t, u, y (or t, r, x); the file has {have}"
                    return "map", file_columns(data, filename, name="your file"), message
            return "ok", (cols["t"], u, y, filename), sample_time(cols["t"], name="your file", path=filename)

        def show(out, _job):
            if out[0] == "map":
                # the question once, beside the upload (the note said it a second time)
                self.mapping.ask(out[1], filename, self.read)
                self.note.object = ""
                self.inputs_changed()
                return
            _, cols, ts = out
            self._uploads += 1              # a new file, even with the same name and length
            self.columns, self._mapping = cols, mapping
            self.result = None
            for d in self.downloads:
                d.disabled = True
            self.mapping.hide()
            t, name = cols[0], cols[3]
            self.note.object = (f"<span class='eha-ok'>Your record: {html.escape(name)}, {t.size} samples every "
                                f"{ts * 1e3:.4g} ms, t from {t[0]:g} to {t[-1]:g} s.</span>")
            self.window_form.values = {"rec_from": "", "rec_to": ""}
            self.window_box.visible = self.detrend.visible = True
            self.inputs_changed()           # a record is loaded: its button now, not when the drawing comes
            self.preview()

        def fail(message):
            self.note.object = f"<span class='eha-warn'>{html.escape(message)}</span>"

        return self.runner.run("reading your record", compute, show, fail=fail, note=self._note)

    # -- preprocessing, drawn as it is chosen ----------------------------------------------------
    def preview(self) -> None:
        """Prepare the record (range, trend) in a worker and draw it; a bad range gets its message."""
        from eha_core.identify.record import prepare_record

        if self.columns is None:
            return
        t, u, y, _ = self.columns
        (t_from, t_to), detrend = self.window(), self.detrend.value

        # the estimate is drawn over the record only if it was made from exactly these inputs (the
        # key holds the file, the range and the trend), decided here, not in the worker
        rec = self.result if self.result is not None and self.view.computed_from == self.run_key() else None

        def compute(_token):
            prepared = prepare_record(t, u, y, detrend=detrend, t_from=t_from, t_to=t_to)
            return prepared, plots.record_data_view(t, u, y, prepared, rec)

        def show(out, _job):
            self.window_form.errors = {}
            self.prepared, view = out
            self._draw_data(view)
            self.inputs_changed()

        def failed(error):
            # the core names the field it refuses ("from t" or "to t"): the message goes beside it
            field = {"to t": "rec_to", "from t": "rec_from"}.get(getattr(error, "field", ""), "rec_from")
            self.window_form.errors = {field: " ".join(str(error).split())}
            self.inputs_changed()

        self.preview_runner.run("preparing your record", compute, show, fail=lambda _m: None, failed=failed)

    def _draw_data(self, view) -> None:
        if self.data_figure is None:
            self.data_figure = plots.RecordDataFigure()
            self.data_figure.update(view)
            self.data_area.objects = [pn.pane.Bokeh(self.data_figure.layout, sizing_mode="stretch_width")]
        else:
            self.data_figure.update(view)
        self.data_area.visible = True

    # -- the estimate --------------------------------------------------------------------------------
    def run(self):
        """H(s) from the prepared record (a worker), shown with its validation, data plot and Bode diagram."""
        from eha_core.identify.record import identify_record

        cfg, key = self.orders(), self.run_key()
        if key is None or self.mapping.waiting:
            return None
        t, u, y, name = self.columns
        (t_from, t_to), detrend = self.window(), self.detrend.value

        def compute(token):
            rec = identify_record(t, u, y, n_poles=cfg.n_poles, n_zeros=cfg.n_zeros,
                                  initial_condition=cfg.initial_condition, input_offset=cfg.input_offset,
                                  detrend=detrend, t_from=t_from, t_to=t_to, input_delay=cfg.input_delay,
                                  cancel=token)
            return rec, plots.record_view(rec), plots.record_data_view(t, u, y, rec.prepared, rec)

        def show(out, _job):
            rec, bode_view, data_view = out
            self.result = rec
            self.summary.object = self._summary(rec, name)
            if self.bode is None:
                self.bode = plots.BodeFigure()
                self.bode.update(bode_view)
                self.area.objects = [self.summary, pn.pane.Bokeh(self.bode.layout, sizing_mode="stretch_width")]
            else:
                self.bode.update(bode_view)
            self._draw_data(data_view)
            ok = bool(rec.estimate.success) and bool(np.all(np.isfinite(rec.estimate.den)))
            self.downloads[0].disabled = self.downloads[1].disabled = not ok
            self.downloads[2].disabled = not ok or rec.bode is None
            self.area.visible = True
            self.view.shown(key)
            self.inputs_changed()
            e = rec.estimate
            if e.success and np.all(np.isfinite(e.den)):
                apply_locked(partial(self.session.post, "board", BoardModel(
                    name="R", kind="record", estimate=e, num=e.num, den=e.den,
                    input_delay=getattr(e, "input_delay", 0.0), ts=rec.ts,
                    description=f"{name}: {e.n_poles} poles, {e.n_zeros} zeros, t ∈ [{rec.prepared.t_from:g}, "
                                f"{rec.prepared.t_to:g}] s, detrend {rec.detrend}; fit {e.fit_percent:.1f} %")))

        return self.runner.run("estimate from your record", compute, show, fail=self._fail, note=self._note)

    @staticmethod
    def _summary(rec, name: str) -> str:
        e, p = rec.estimate, rec.prepared
        parts = [f"<h4>Your record: {html.escape(name)}</h4>"]
        alert = estimate_alert(e)
        if alert:
            parts.append(f"<div class='eha-warn'>{alert}</div>")
        if e.success and np.all(np.isfinite(e.den)):
            parts.append(tf_html("Ĥ(s)", e.num, e.den, f"from the first {rec.n_estimation} samples "
                                 f"(t ∈ [{p.t_from:g}, {p.t_split:g}] s); {term('fit', f'fit {e.fit_percent:.2f} %')}"))
            if rec.validation is not None:
                parts.append(f"<p>Validated on the last {rec.t.size - rec.n_estimation} samples: fit "
                             f"<b>{rec.validation.fit_percent:.2f} %</b>.</p>")
            parts.append(estimation_sentences(e))
        delay = getattr(e, "input_delay", 0.0) or 0.0
        if delay:
            std = getattr(e, "input_delay_std", None)
            parts.append(f"<p>With an input delay e<sup>−sτ</sup>, τ = <b>{delay * 1e3:.4g} ms</b> = "
                         f"{delay / rec.ts:.3g} samples"
                         + (f" (estimated, standard error {std * 1e3:.3g} ms)" if std is not None and np.isfinite(std)
                            else "") + ".</p>")
        if rec.detrend != "none":
            parts.append(f"<p class='eha-note'>{'The mean' if rec.detrend == 'mean' else 'A linear trend'} was "
                         "removed from u and y first.</p>")
        return "".join(parts)

    def estimate_bytes(self, kind: str) -> bytes:
        """The record's estimate with its intervals, the preprocessing and the fits (CSV or JSON)."""
        rec, p = self.result, self.result.prepared
        settings = {"file": self.columns[3] if self.columns else "", "columns": self._mapping or {},
                    "t_from_s": p.t_from, "t_to_s": p.t_to, "detrend": p.detrend,
                    "n_estimation": rec.n_estimation, "n_validation": int(rec.t.size - rec.n_estimation)}
        return tf_estimate_bytes(rec.estimate, kind, settings=settings, fits={
            "fit_percent": rec.estimate.fit_percent,
            "validation_fit_percent": None if rec.validation is None else rec.validation.fit_percent})

    # -- the section's protocol ----------------------------------------------------------------------
    def settings(self) -> dict[str, str]:
        return {**{k: str(self.window_form.values.get(k, "")) for k in _WINDOW_FIELDS},
                "rec_detrend": str(self.detrend.value)}

    def load(self, texts) -> None:
        window = {k: v for k, v in texts.items() if k in _WINDOW_FIELDS}
        if window:
            self.window_form.set_values(**window)
        if texts.get("rec_detrend") in DETRENDS.values():
            self.detrend.value = texts["rec_detrend"]

    def result_views(self) -> list:
        return [self.view]

    def kept_work(self) -> KeptWork | None:
        upload = None
        if self.columns is not None and self._upload is not None:
            data, name = self._upload
            upload = StoredFile(self.key, name, data, dict(self._mapping) if self._mapping else None)
        views = ["freq-record"] if self.view.is_current else []
        if not views and upload is None:
            return None
        return KeptWork({"views": views}, upload)

    @classmethod
    def restore_work(cls, kept: KeptWork, texts) -> list[RestoreStep]:
        upload = kept.file
        if upload is None:
            return []
        steps = [read_kept(upload),
                 # reading a record clears its range: the kept one goes back after it
                 RestoreStep("", lambda section: section.load(texts))]
        if "freq-record" in (kept.run or {}).get("views", ()):
            steps.append(RestoreStep(cls.title, lambda section: section.run()))
        return steps

    def snapshot(self) -> SectionSnapshot:
        # the file's columns are never changed in place: a new upload makes new arrays
        return SectionSnapshot(self.key, self.title, self.settings(), stale=self.is_stale(),
                               content=(self.result, self.columns))

    @classmethod
    def report(cls, snapshot: SectionSnapshot, hidden=()) -> ReportPart | None:
        rec, columns = snapshot.content or (None, None)
        if rec is None or columns is None:
            return None
        t, u, y, name = columns
        bode = plots.BodeFigure()
        bode.update(plots.record_view(rec))
        data = plots.RecordDataFigure()
        data.update(plots.record_data_view(t, u, y, rec.prepared, rec))
        return ReportPart("Transfer function from your own record", stale_note(snapshot) + cls._summary(rec, name)
                          + "{{record_data}}{{record_bode}}", {"record_data": data.layout, "record_bode": bode.layout})

    # -- layout ------------------------------------------------------------------------------------
    def controls(self) -> list:
        return [self.note, self.upload, self.mapping.panel, self.window_box, self.detrend, self.button,
                pn.FlexBox(*self.downloads, width=270, sizing_mode="fixed")]

    def results(self) -> list:
        return [self.data_area, self.view.banner, self.area]
