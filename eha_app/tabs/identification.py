"""Tab 3: identification, in the time domain (least squares) and the frequency domain."""

from __future__ import annotations

import panel as pn

from ..state import AppState
from ..tasks import SessionRunner, apply_locked, frozen_models, watch
from .board import BoardInbox, ModelBoard
from .frequency import FREQ_DEFAULTS, FREQ_FORM, FrequencyPanel, parse_freq
from .least_squares import LSE_DEFAULTS, LSE_FORM, LeastSquaresPanel, LseRequest, parse_lse
from .study import StudyPanel

__all__ = ["IdentificationTab", "LeastSquaresPanel", "FrequencyPanel", "ModelBoard", "LseRequest", "LSE_FORM",
           "LSE_DEFAULTS", "FREQ_FORM", "FREQ_DEFAULTS", "parse_lse", "parse_freq"]


class IdentificationTab(pn.viewable.Viewer):
    """Step 3 of the paper: identification (Fig. 17), time and frequency domain.

    The frequency-domain panel is built when first shown.
    """

    def __init__(self, state: AppState, *, runner: SessionRunner | None = None, query: dict | None = None,
                 **kwargs):
        super().__init__(**kwargs)
        self.state = state
        self.runner = runner if runner is not None else SessionRunner(state)
        self._query = query
        # every estimate of the session lands on the board (made, with its figures, when first shown)
        self.inbox = BoardInbox()
        self.board: ModelBoard | None = None
        self.lse = LeastSquaresPanel(state, self.runner, query)
        self.lse.board = self.inbox
        self.freq: FrequencyPanel | None = None
        self._freq_slot = pn.Column(pn.pane.HTML("<p class='eha-note'>Preparing the frequency domain…</p>"),
                                    sizing_mode="stretch_width")
        self._board_slot = pn.Column(pn.pane.HTML("<p class='eha-note'>Preparing the model board…</p>"),
                                     sizing_mode="stretch_width")
        self.study: StudyPanel | None = None
        self._study_slot = pn.Column(pn.pane.HTML("<p class='eha-note'>Preparing the study…</p>"),
                                     sizing_mode="stretch_width")
        self.tabs = pn.Tabs(("Time domain: least squares", self.lse),
                            ("Frequency domain: transfer function", self._freq_slot),
                            ("Model board", self._board_slot),
                            ("Study over seeds", self._study_slot),
                            dynamic=False, sizing_mode="stretch_width", css_classes=["eha-ident-tabs"])
        watch(self.tabs, self._on_tab, "active")

    def _on_tab(self, event) -> None:
        if event.new == 1:
            apply_locked(self.frequency_panel)
        elif event.new == 2:
            apply_locked(self.board_panel)
        elif event.new == 3:
            apply_locked(self.study_panel)

    def study_panel(self) -> StudyPanel:
        """The study, built now if never shown."""
        if self.study is None:
            with frozen_models():
                self.study = StudyPanel(self.state, self.runner, self._query)
                self._study_slot.objects = [self.study]
        return self.study

    def board_panel(self) -> ModelBoard:
        """The model board, with its figures built now if never shown."""
        if self.board is None:
            with frozen_models():
                self.board = self.inbox.board = ModelBoard(self.state, self.runner, self._query)
                self.board.build()
                for model in self.inbox.pending:
                    self.board.add(model)
                self.inbox.pending.clear()
                self._board_slot.objects = [self.board]
        return self.board

    def frequency_panel(self) -> FrequencyPanel:
        """The frequency-domain panel, built now if never shown."""
        if self.freq is None:
            with frozen_models():
                self.freq = FrequencyPanel(self.state, self.runner, self._query)
                self.freq.board = self.freq.record.board = self.inbox
                self._freq_slot.objects = [self.freq]
        return self.freq

    def __panel__(self):
        return self.tabs
