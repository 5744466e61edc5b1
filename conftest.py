from pathlib import Path

import pytest

@pytest.fixture(scope="session", autouse=True)
def no_secret_in_any_server_log(tmp_path_factory):
    """After the whole run: grep every server log the run wrote for every exercise's secret and
    its students' hidden values (tests/log_audit.py); a find fails the run."""
    yield
    from tests.log_audit import audit

    ui_log = Path(__file__).parent / ".pytest_cache" / "ui_server.log"
    leaks = audit(tmp_path_factory.getbasetemp(), [ui_log])
    assert not leaks, "secrets in the servers' logs:\n" + "\n".join(leaks[:20])
