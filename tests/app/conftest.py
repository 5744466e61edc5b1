import asyncio

import pytest

import eha_app.sections  # noqa: F401 - the page's sections register themselves (sessions of these tests use them)


@pytest.fixture
def run_async():
    """Run a coroutine (the tabs' async button handlers) to completion."""
    def runner(coro):
        return asyncio.run(coro)
    return runner
