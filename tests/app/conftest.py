import asyncio

import pytest


@pytest.fixture
def run_async():
    """Run a coroutine (the tabs' async button handlers) to completion."""
    def runner(coro):
        return asyncio.run(coro)
    return runner
