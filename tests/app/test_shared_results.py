"""Pure computations shared by sessions: computed once per key, awaited by the requests that arrive meanwhile,
never failed or cancelled for one student by another's closed page."""

import threading
import time

import pytest

from eha_app.runtime.shared import SharedResults
from eha_app.session import Session
from eha_app.session.state import AppState
from eha_core.cancel import Cancelled, CancelToken


def test_requests_with_one_key_compute_once_and_share_the_result():
    store = SharedResults()
    calls = []
    gate = threading.Event()

    def slow(_token):
        calls.append(1)
        gate.wait(5)
        return object()

    out = []
    threads = [threading.Thread(target=lambda: out.append(store.get("k", slow))) for _ in range(8)]
    for t in threads:
        t.start()
    time.sleep(0.2)
    gate.set()
    for t in threads:
        t.join(5)
    assert len(calls) == 1 and len(out) == 8 and all(o is out[0] for o in out)
    assert (store.misses, store.joins + store.hits) == (1, 7)
    assert store.get("k", slow) is out[0] and len(calls) == 1         # later: from the store
    assert store.get("other", lambda _t: 2) == 2


def test_a_waiting_request_stops_on_its_own_cancel_and_the_owners_failure_is_not_the_waiters():
    store = SharedResults()
    started, gate = threading.Event(), threading.Event()

    def owner_run(token):
        started.set()
        gate.wait(5)
        raise Cancelled("the first page was closed")

    first = threading.Thread(target=lambda: pytest.raises(Cancelled, store.get, "k", owner_run))
    first.start()
    started.wait(5)
    # a waiter whose own page closes stops waiting at once
    token = CancelToken()
    token.cancel("closed")
    with pytest.raises(Cancelled):
        store.get("k", lambda _t: 1, token)
    # a waiter whose owner is cancelled computes the result itself
    result = []
    waiter = threading.Thread(target=lambda: result.append(store.get("k", lambda _t: "mine")))
    waiter.start()
    time.sleep(0.1)
    gate.set()
    first.join(5)
    waiter.join(5)
    assert result == ["mine"]


def test_the_store_keeps_its_most_recent_results():
    store = SharedResults(maxsize=3)
    for k in range(5):
        store.get(k, lambda _t, k=k: k)
    store.get(2, lambda _t: "again")              # kept
    assert store.get(0, lambda _t: "again") == "again"       # dropped, computed again
    assert store.get(2, lambda _t: "never") == 2


def test_two_students_with_the_same_inputs_share_a_run_and_another_actuator_does_not():
    a, b, c = (Session(AppState()) for _ in range(3))
    c.state.set_text("M", "5000")
    runs = []
    for s in (a, b, c):
        lse = s.build("least_squares")
        assert lse.run().state == "done"
        runs.append(lse)
    assert runs[0].result is runs[1].result and runs[0].last_data is runs[1].last_data
    assert runs[2].result is not runs[0].result and runs[2].result.estimates["M"] != runs[0].result.estimates["M"]
    freqs = [s.build("frequency") for s in (a, b)]
    for f in freqs:
        f.run()
    assert freqs[0].result.estimate is freqs[1].result.estimate
