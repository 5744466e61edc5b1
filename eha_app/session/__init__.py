"""A page's session and its sections: who owns what a student sees.

:class:`~eha_app.session.session.Session` (one per page) owns the state, the
runner, the page's address, the exercise identity and the sections;
:class:`~eha_app.session.section.Section` is one tab or panel, registered in
page order in :data:`~eha_app.session.section.SECTIONS`.
"""

from .section import (
    SECTIONS,
    GuideStep,
    KeptWork,
    Placement,
    ReportPart,
    RestoreStep,
    Section,
    SectionRegistry,
    SectionSnapshot,
    run_off_notice,
    stale_note,
)
from .session import MAX_SETTINGS_BYTES, SETTINGS_FORMAT, Session, SessionSnapshot, SettingsError

__all__ = ["Session", "SessionSnapshot", "Section", "SectionSnapshot", "ReportPart", "GuideStep", "KeptWork",
           "RestoreStep", "Placement", "SectionRegistry", "SECTIONS", "SettingsError", "SETTINGS_FORMAT",
           "MAX_SETTINGS_BYTES", "stale_note", "run_off_notice"]
