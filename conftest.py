import os
from pathlib import Path

import pytest

# Every server the suite starts runs in strict mode: a change to a page made outside its
# document's lock raises at once, naming the line that made it (eha_app/runtime/patches.py).
os.environ.setdefault("EHA_STRICT", "1")

@pytest.fixture(scope="session", autouse=True)
def no_secret_in_any_server_log(tmp_path_factory):
    """After the whole run: grep every server log the run wrote for every exercise's secret, its
    students' hidden values and a page changed outside its lock (tests/log_audit.py); a find
    fails the run."""
    yield
    from tests.log_audit import audit

    ui_log = Path(__file__).parent / ".pytest_cache" / "ui_server.log"
    leaks = audit(tmp_path_factory.getbasetemp(), [ui_log])
    assert not leaks, "in the servers' logs:\n" + "\n".join(leaks[:20])
