import asyncio

import pytest

import eha_app.sections  # noqa: F401 - the page's sections register themselves (sessions of these tests use them)


@pytest.fixture
def run_async():
    """Run a coroutine (the tabs' async button handlers) to completion."""
    def runner(coro):
        return asyncio.run(coro)
    return runner


@pytest.fixture(scope="session", autouse=True)
def _stop_the_studies_child():
    """The studies of these tests start the process-wide child for long work: stopped at the end."""
    yield
    from eha_app.runtime import background

    if background._default is not None:
        background._default.shutdown()


@pytest.fixture
def lab_exercise(tmp_path, monkeypatch):
    """A lab whose four main parameters are hidden, each student's own, served by the app (EHA_EXERCISE):
    (the exercise, its file)."""
    from eha_core.exercise import Exercise

    ex = Exercise.new(hide=("M", "B", "Af", "beta_e"), vary=0.25, tolerance=0.05, title="Lab 3", secret="5a" * 32)
    path = tmp_path / "class.json"
    ex.save(path)
    monkeypatch.setenv("EHA_EXERCISE", str(path))
    return ex, path
