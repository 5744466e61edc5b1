"""Computations in worker threads never touch Bokeh, and many at once all succeed.

Before, the frequency experiment rendered HoloViews figures in its worker
thread; the renderer switches Bokeh's process-wide property validation off
while it works, and overlapping renders could leave it off for good: every
later figure failed ("'str' object has no attribute 'update'") and new
students got a blank page. Now a worker computes arrays only; figures are
built and updated on the session's document.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from bokeh.core.has_props import HasProps
from bokeh.core.property.bases import Property

from eha_app.render import plots
from eha_app.runtime.jobs import JobQueue
from eha_app.sections.frequency import parse_freq
from eha_app.session import Session
from eha_app.session.state import AppState
from eha_core.experiments import run_frequency_identification


def test_many_frequency_experiments_at_once_build_no_bokeh_model_and_all_succeed(monkeypatch):
    made_in = []
    original = HasProps.__init__

    def spy(self, *args, **kwargs):
        made_in.append(threading.current_thread().name)
        original(self, *args, **kwargs)

    monkeypatch.setattr(HasProps, "__init__", spy)
    tab = Session(AppState())
    panel = tab.build("frequency")
    cfg, errors = parse_freq({**panel.form.values, "freq_seed": "0"})
    assert not errors
    params = tab.state.params

    def compute(seed):
        from dataclasses import replace

        fi = run_frequency_identification(params, replace(cfg, seed=seed))
        return fi, plots.frequency_view(fi)

    made_in.clear()
    with ThreadPoolExecutor(6, thread_name_prefix="worker") as pool:
        outs = list(pool.map(compute, range(12)))
    assert not [name for name in made_in if name.startswith("worker")]
    assert Property._should_validate                      # Bokeh's process-wide switch untouched
    assert all(fi.success for fi, _ in outs)
    fits = [fi.estimate.fit_percent for fi, _ in outs]
    assert min(fits) > 90.0
    # each result shows on its own figures, built on the page's side
    figures = [plots.BodeFigure() for _ in outs]
    for fig, (fi, view) in zip(figures, outs, strict=True):
        fig.update(view)
        np.testing.assert_allclose(fig.points.data["w"], fi.etfe.w.astype(np.float32))


def test_one_student_clicking_four_times_gets_one_result_and_the_others_theirs():
    queue = JobQueue(workers=2)
    try:
        tabs = [Session(AppState()) for _ in range(3)]
        results = {}
        done = threading.Event()
        jobs = []
        for i, tab in enumerate(tabs):
            params = tab.state.params
            cfg, _ = parse_freq(tab.build("frequency").form.values)
            clicks = 4 if i == 0 else 1
            for _ in range(clicks):
                def on_done(job, i=i):
                    if job.state == "done":
                        results.setdefault(i, []).append(job.result)
                    if all(j.finished for j in jobs):
                        done.set()
                job, _ = queue.submit(i, lambda token, p=params, c=cfg: run_frequency_identification(
                    p, c, cancel=token), label="freq", on_done=on_done)
                jobs.append(job)
                while job.state == "queued" and len(jobs) == 1:
                    threading.Event().wait(0.001)      # the first click has started
        assert done.wait(120)
        states = [j.state for j in jobs[:4]]
        # the first click runs; of the three while it ran, the last replaced the others
        assert states.count("done") == 2 and states.count("replaced") == 2
        assert all(len(results[i]) == 1 for i in (1, 2))
        assert all(fi.success for rs in results.values() for fi in rs)
    finally:
        queue.shutdown()


def test_a_server_process_gives_each_blas_library_one_thread():
    """The students' runs are a server's parallel work: numpy's and scipy's OpenBLAS get one thread each
    (their own pool only spun beside the workers), in a process of its own here as in `eha serve`."""
    # as `eha serve` starts: numpy loaded (the core), scipy.linalg (its own OpenBLAS) not yet
    script = ("import json, sys\n"
              "import eha_core.params\n"
              "from threadpoolctl import threadpool_info\n"
              "from eha_app.runtime.serving import one_blas_thread\n"
              "before = [i['num_threads'] for i in threadpool_info() if i['user_api'] == 'blas']\n"
              "names = one_blas_thread()\n"
              "import scipy.linalg, scipy.optimize\n"
              "after = [i['num_threads'] for i in threadpool_info() if i['user_api'] == 'blas']\n"
              "print(json.dumps([names, before, after]))\n")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120,
                          env={**os.environ, "OPENBLAS_NUM_THREADS": "2"})
    assert done.returncode == 0, done.stderr[-2000:]
    names, before, after = json.loads(done.stdout.strip().splitlines()[-1])
    assert names and set(names) <= {"openblas", "mkl", "blis"}
    assert len(after) == len(names) and after == [1] * len(after) and max(before) == 2
