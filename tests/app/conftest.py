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
