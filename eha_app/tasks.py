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
from panel.io.state import set_curdoc

__all__ = ["run_task", "apply_locked"]

log = logging.getLogger("eha_app")

#: Show the loading indicator only when a computation takes longer than this.
LOADING_DELAY_S = 0.2


def apply_locked(fn: Callable[[], None], doc=None) -> None:
    """Run ``fn`` on the event loop with ``doc``'s lock, as Panel's current document.

    ``doc`` is the session's document, captured when the user's event arrived:
    after an ``await`` Panel's current document may belong to another session.
    Going through ``pn.state.execute`` under ``set_curdoc`` matters: with a bare
    Bokeh next-tick callback Panel does not know which session it updates and
    about one update in 25 never reached the browser (measured by clicking the
    same run button 40 times).
    """
    doc = doc if doc is not None else pn.state.curdoc
    if doc is not None and getattr(doc, "session_context", None) is not None:
        with set_curdoc(doc):
            pn.state.execute(fn, schedule=True)
    else:
        fn()


async def run_task(compute: Callable[[], object], apply: Callable[[object, float], None],
                   fail: Callable[[str], None], busy: list,
                   apply_bokeh: Callable[[object, float], None] | None = None) -> None:
    """Compute in a thread, then show the result.

    ``apply_bokeh(result, seconds)`` changes raw Bokeh models and runs under the
    session document's lock; ``apply(result, seconds)`` changes Panel
    components and runs right here in the coroutine, where Panel schedules
    the updates itself. (Panel updates made inside a bare Bokeh next-tick
    callback were occasionally never sent to the browser: 1 in ~25 clicks.)
    ``busy`` are Panel components shown as loading meanwhile. An exception
    calls ``fail(message)`` instead.
    """
    doc = pn.state.curdoc
    t0 = time.perf_counter()
    future = asyncio.get_running_loop().run_in_executor(None, compute)
    try:
        # the loading indicator only for runs a user would wait for: toggling it
        # re-lays-out the plots, which costs more than a 20 ms simulation
        done, _ = await asyncio.wait({future}, timeout=LOADING_DELAY_S)
        if not done:
            for c in busy:
                c.loading = True
        result = await future
        elapsed = time.perf_counter() - t0
        if apply_bokeh is not None:
            apply_locked(lambda: apply_bokeh(result, elapsed), doc)
        apply(result, elapsed)
    except Exception as exc:  # noqa: BLE001 - any failure becomes a message in the page
        log.warning("computation failed: %s\n%s", exc, traceback.format_exc())
        fail(" ".join(str(exc).split()) or type(exc).__name__)
    finally:
        for c in busy:
            if c.loading:
                c.loading = False
