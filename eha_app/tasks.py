"""Running a computation for one session without blocking the others.

A run happens in a worker thread (the compiled kernels release the GIL), while
the page shows a loading indicator; the results are then applied to the
session's document under its lock (Bokeh models may only change there). An
exception becomes a message in the page: the session keeps working.
"""

from __future__ import annotations

import asyncio
import logging
import time
import traceback
from typing import Callable

import panel as pn

__all__ = ["run_task", "apply_locked"]

log = logging.getLogger("eha_app")


def apply_locked(fn: Callable[[], None]) -> None:
    """Run ``fn`` with the session document's lock (or directly outside a server)."""
    doc = pn.state.curdoc
    if doc is not None and getattr(doc, "session_context", None) is not None:
        doc.add_next_tick_callback(fn)
    else:
        fn()


async def run_task(compute: Callable[[], object], apply: Callable[[object, float], None],
                   fail: Callable[[str], None], busy: list) -> None:
    """Compute in a thread, then ``apply(result, seconds)`` under the lock.

    ``busy`` are Panel components shown as loading meanwhile. An exception in
    ``compute`` or ``apply`` calls ``fail(message)`` instead.
    """
    for c in busy:
        c.loading = True
    t0 = time.perf_counter()
    try:
        result = await asyncio.get_running_loop().run_in_executor(None, compute)
    except Exception as exc:  # noqa: BLE001 - any failure becomes a message in the page
        log.warning("computation failed: %s\n%s", exc, traceback.format_exc())
        message = " ".join(str(exc).split()) or type(exc).__name__

        def show_failure():
            for c in busy:
                c.loading = False
            fail(message)

        apply_locked(show_failure)
        return
    elapsed = time.perf_counter() - t0

    def finish():
        try:
            apply(result, elapsed)
        except Exception as exc:  # noqa: BLE001
            log.warning("updating the page failed: %s\n%s", exc, traceback.format_exc())
            fail(" ".join(str(exc).split()) or type(exc).__name__)
        finally:
            for c in busy:
                c.loading = False

    apply_locked(finish)
