"""Chunked integration (same bits, bounded memory), cost estimates, and cancellation."""

from __future__ import annotations

import threading
import time
import tracemalloc

import numpy as np
import pytest

import eha_core.simulate as sim
from eha_core.cancel import Cancelled, CancelToken
from eha_core.experiments import FrequencyExperiment, lse_cost, run_frequency_identification
from eha_core.params import ActuatorParams
from eha_core.signals import Sine, WhiteNoise
from eha_core.simulate import simulate, simulate_closed_loop, simulate_many, simulation_cost

FIELDS = ("t", "x", "v", "p1", "p2", "u", "d")


def same(a, b):
    for name in FIELDS:
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    if a.r is not None or b.r is not None:
        np.testing.assert_array_equal(a.r, b.r)
    assert (a.success, a.message) == (b.success, b.message)


@pytest.fixture
def tiny_chunks(monkeypatch):
    """Run twice: in one chunk, then in chunks of a few output intervals."""
    def run(fn):
        monkeypatch.setattr(sim, "CHUNK_STEPS", 10**9)
        whole = fn()
        monkeypatch.setattr(sim, "CHUNK_STEPS", 7)
        return whole, fn()
    return run


@pytest.mark.parametrize("model", ["nonlinear", "linear"])
def test_open_loop_in_chunks_is_bitwise_the_same(tiny_chunks, model):
    whole, chunked = tiny_chunks(lambda: simulate(u=Sine(6.0, 2.0), d=WhiteNoise(2000.0, seed=3, hold_s=1e-3),
                                                  t_end=0.753, dt=1e-3, model=model))
    same(whole, chunked)


def test_batches_in_chunks_are_bitwise_the_same(tiny_chunks):
    us = [Sine(2.0, 2.0), Sine(6.0, 2.0), Sine(9.0, 5.0)]
    ds = [None, Sine(5e3, 1.0), WhiteNoise(500.0, seed=1, hold_s=2e-3)]
    for parallel in (True, False):
        whole, chunked = tiny_chunks(lambda: simulate_many(None, us, ds, t_end=0.5, dt=2e-3, parallel=parallel))
        for a, b in zip(whole, chunked):
            same(a, b)


@pytest.mark.parametrize("controller, u_limit", [("zoh", None), ("zoh", 3.0), ("continuous", None),
                                                 ("continuous", 2.0)])
def test_closed_loop_in_chunks_is_bitwise_the_same(tiny_chunks, controller, u_limit):
    r = np.sin(np.arange(83) * 0.3) * 0.05
    whole, chunked = tiny_chunks(lambda: simulate_closed_loop(r=r, ts=0.01, kp=10.0, controller=controller,
                                                              u_limit=u_limit, d=Sine(3e3, 1.0)))
    same(whole, chunked)


def test_a_run_that_fails_reports_the_same_step_in_chunks(tiny_chunks):
    # an absurd bulk modulus on the linearised model diverges: the failure time
    # is the global one, whatever chunk it happens in
    p = ActuatorParams(beta_e=1e14)
    whole, chunked = tiny_chunks(lambda: simulate(p, u=Sine(6.0, 2.0), t_end=0.5, model="linear"))
    assert not whole.success
    same(whole, chunked)


def test_memory_follows_the_output_not_the_steps():
    # 2000 samples at Ts = 0.5 s: 1000 s of closed loop, 2 M steps; the stage
    # samples of r and d over all steps would take 2 x 2 M x 3 x 8 B = 96 MB
    r = np.sin(np.arange(2001) * 0.01) * 0.01
    steps = 2000 * round(0.5 / sim.DEFAULT_H_MAX)
    tracemalloc.start()
    try:
        res = simulate_closed_loop(r=r, ts=0.5, kp=10.0)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert res.success and res.t.size == 2001
    assert peak < steps * 3 * 8 / 4, f"peak {peak / 2**20:.1f} MB"
    est = simulation_cost(1000.0, 0.5, ts=0.5)
    assert est.steps == steps
    assert 0.5 < est.peak_bytes / peak < 2.0, (est.peak_bytes, peak)


@pytest.mark.parametrize("t_end, dt, n_runs", [(5.0, 1e-3, 4), (60.0, 1e-3, 2)])
def test_cost_estimate_is_within_a_factor_two_of_the_measured_peak(t_end, dt, n_runs):
    us = [Sine(2.0 + k, 2.0) for k in range(n_runs)]
    tracemalloc.start()
    try:
        simulate_many(None, us, t_end=t_end, dt=dt)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    est = simulation_cost(t_end, dt, n_runs=n_runs)
    assert est.steps == n_runs * round(t_end / sim.DEFAULT_H_MAX)
    assert 0.5 < est.peak_bytes / peak < 2.0, (est.peak_bytes, peak)


def test_frequency_experiment_cost_counts_both_runs_and_tfest():
    cfg = FrequencyExperiment(n_samples=20000, ts=0.5)
    cost = cfg.cost()
    assert cost.steps == 2 * 19999 * round(0.5 / sim.DEFAULT_H_MAX)
    small = FrequencyExperiment().cost()
    assert small.steps == 2 * 999 * round(0.01 / sim.DEFAULT_H_MAX)
    assert cost.peak_bytes > small.peak_bytes
    assert lse_cost(20.0).steps == 4 * lse_cost(5.0).steps


def cancel_after(token, seconds):
    timer = threading.Timer(seconds, token.cancel, args=("test",))
    timer.start()
    return timer


def test_a_long_closed_loop_stops_soon_after_cancel():
    r = np.sin(np.arange(4001) * 0.01) * 0.01          # 2000 s, 4 M steps
    t0 = time.perf_counter()
    simulate_closed_loop(r=r, ts=0.5)
    full = time.perf_counter() - t0
    token = CancelToken()
    cancel_after(token, 0.05)
    t0 = time.perf_counter()
    with pytest.raises(Cancelled, match="test"):
        simulate_closed_loop(r=r, ts=0.5, cancel=token)
    stopped = time.perf_counter() - t0
    assert stopped < 0.5 * full, (stopped, full)


def test_the_frequency_identification_stops_soon_after_cancel():
    cfg = FrequencyExperiment(n_samples=4000)
    t0 = time.perf_counter()
    run_frequency_identification(config=cfg)
    full = time.perf_counter() - t0
    token = CancelToken()
    cancel_after(token, 0.05)
    t0 = time.perf_counter()
    with pytest.raises(Cancelled):
        run_frequency_identification(config=cfg, cancel=token)
    assert time.perf_counter() - t0 < 0.5 * full


def test_a_cancelled_token_stops_before_any_work():
    token = CancelToken()
    token.cancel("the page was closed")
    with pytest.raises(Cancelled, match="the page was closed"):
        simulate(u=Sine(1.0, 1.0), t_end=1.0, cancel=token)


@pytest.mark.parametrize("n_samples, ts", [(1000, 0.01), (4000, 0.01), (1000, 0.2)])
def test_frequency_experiment_memory_estimate_is_within_a_factor_two(n_samples, ts):
    cfg = FrequencyExperiment(n_samples=n_samples, ts=ts)
    tracemalloc.start()
    try:
        run_frequency_identification(config=cfg)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert 0.5 < cfg.cost().peak_bytes / peak < 2.0, (cfg.cost().peak_bytes, peak)


def test_least_squares_memory_estimate_is_within_a_factor_two():
    from eha_core.experiments import run_lse

    tracemalloc.start()
    try:
        run_lse(t_end=5.0)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert 0.5 < lse_cost(5.0).peak_bytes / peak < 2.0, (lse_cost(5.0).peak_bytes, peak)
