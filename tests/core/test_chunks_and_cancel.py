"""Chunked integration (same bits, bounded memory), cost estimates, and cancellation."""

from __future__ import annotations

import math
import sys
import threading
import time
import tracemalloc

import numpy as np
import pytest

import eha_core.identify._oe_criterion as oe_criterion
import eha_core.identify._srivc as srivc_mod
import eha_core.simulate as sim
from eha_core.cancel import Cancelled, CancelToken
from eha_core.experiments import (
    FrequencyExperiment,
    lse_cost,
    lse_data,
    lse_resimulation,
    lse_simulation,
    run_frequency_identification,
    run_lse,
    run_lse_table,
    run_paper_cases,
)
from eha_core.identify.lse import identify_lse
from eha_core.identify.tfest import oe_fit, simulate_tf, tfest
from eha_core.params import ActuatorParams
from eha_core.signals import Sine, WhiteNoise
from eha_core.simulate import (
    simulate,
    simulate_closed_loop,
    simulate_many,
    simulation_cost,
)

FIELDS = ("t", "x", "v", "p1", "p2", "u", "d")


def same(a, b):
    for name in FIELDS:
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    if a.r is not None or b.r is not None:
        np.testing.assert_array_equal(a.r, b.r)
    assert (a.success, a.message) == (b.success, b.message)


def peak_bytes(fn):
    tracemalloc.start()
    try:
        out = fn()
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return peak, out


# -- the same bits in chunks -------------------------------------------------------

def _sine_fn(t):
    """Sine(6.0, 2.0) as a function of t: its jumps unknown, it takes the chunked fixed-step RK4."""
    return 6.0 * np.sin(4.0 * np.pi * np.asarray(t, dtype=float))


@pytest.fixture
def in_chunks(monkeypatch):
    """``run(fn, t_end, dt, ts)``: ``fn()`` in one chunk, then in chunks of 1 and
    7 periods (a period: the least common multiple of the output and controller
    intervals, in steps). The case must end inside a 7-period chunk."""
    def run(fn, t_end, dt, ts=None):
        _, sub, every, n_steps, _ = sim._grid(t_end, dt, sim.DEFAULT_H_MAX, ts)
        period = math.lcm(sub, every)
        assert n_steps > 14 * period and n_steps % (7 * period) != 0, "choose a case that ends inside a chunk"
        monkeypatch.setattr(sim, "CHUNK_STEPS", 10**9)
        assert sim._chunk_length(n_steps, sub, every) >= n_steps
        whole = fn()
        chunked = []
        for k in (1, 7):
            monkeypatch.setattr(sim, "CHUNK_STEPS", k * period)
            assert sim._chunk_length(n_steps, sub, every) == k * period
            chunked.append(fn())
        return whole, chunked
    return run


@pytest.mark.parametrize("call", [
    lambda: simulate_closed_loop(r=R83, ts=0.01, d=Sine(3e3, 1.0)),
    lambda: simulate_closed_loop(r=Sine(0.05, 1.5), ts=0.01, dt=0.0025, t_end=0.8275, controller="continuous",
                                 u_limit=4.0),
    lambda: simulate(u=Sine(6.0, 2.0), d=WhiteNoise(2000.0, seed=3, hold_s=1e-3), t_end=0.753),
    lambda: simulate_many(None, [Sine(2.0, 2.0), Sine(9.0, 5.0)], [None, Sine(5e3, 1.0)], t_end=0.5),
], ids=["zoh", "continuous", "open loop", "batch"])
def test_pausing_the_adaptive_kernel_for_cancel_gives_the_same_bits(monkeypatch, call):
    # a pause (to check for a cancel) comes after an accepted step, whose state the next call takes up
    whole = call()
    monkeypatch.setattr(sim, "CANCEL_CHECK_STEPS", 7)
    paused = call()
    as_list = lambda runs: runs if isinstance(runs, list) else [runs]       # noqa: E731
    for a, b in zip(as_list(whole), as_list(paused), strict=True):
        same(a, b)


def test_chunk_length_is_a_multiple_of_the_output_and_controller_periods(monkeypatch):
    monkeypatch.setattr(sim, "CHUNK_STEPS", 1010)
    assert sim._chunk_length(10**6, 20, 8) == 1000          # lcm 40
    assert sim._chunk_length(10**6, 2, 1) == 1010
    monkeypatch.setattr(sim, "CHUNK_STEPS", 7)
    assert sim._chunk_length(10**6, 20, 8) == 40            # never less than one period


@pytest.mark.parametrize("model", ["nonlinear", "linear"])
def test_open_loop_in_chunks_is_bitwise_the_same(in_chunks, model):
    # the noise is held per 1 ms output sample, two integration steps
    whole, chunked = in_chunks(lambda: simulate(u=Sine(6.0, 2.0), d=WhiteNoise(2000.0, seed=3, hold_s=1e-3),
                                                t_end=0.753, dt=1e-3, model=model), 0.753, 1e-3)
    for run in chunked:
        same(whole, run)


@pytest.mark.parametrize("parallel", [True, False])
def test_batches_in_chunks_are_bitwise_the_same(in_chunks, parallel):
    us = [Sine(2.0, 2.0), Sine(6.0, 2.0), Sine(9.0, 5.0)]
    ds = [None, Sine(5e3, 1.0), WhiteNoise(500.0, seed=1, hold_s=2e-3)]
    whole, chunked = in_chunks(lambda: simulate_many(None, us, ds, t_end=0.5, dt=2e-3, parallel=parallel),
                               0.5, 2e-3)
    for runs in chunked:
        for a, b in zip(whole, runs, strict=True):
            same(a, b)


R83 = np.sin(np.arange(83) * 0.3) * 0.05       # 0.82 s of reference samples at ts = 0.01 s


@pytest.mark.parametrize("controller, u_limit", [("zoh", None), ("zoh", 3.0), ("continuous", None),
                                                 ("continuous", 2.0)])
@pytest.mark.parametrize("dt", [None, 0.0025, 0.02])   # dt = ts, ts / 4, 2 ts
def test_closed_loop_in_chunks_is_bitwise_the_same(in_chunks, controller, u_limit, dt):
    whole, chunked = in_chunks(lambda: simulate_closed_loop(r=R83, ts=0.01, dt=dt, kp=10.0, controller=controller,
                                                            u_limit=u_limit, d=Sine(3e3, 1.0)),
                               0.82, dt or 0.01, 0.01)
    for run in chunked:
        same(whole, run)


@pytest.mark.parametrize("controller", ["zoh", "continuous"])
def test_closed_loop_ending_between_controller_instants_in_chunks(in_chunks, controller):
    # 331 outputs of 2.5 ms: the run ends 15 steps after a controller instant,
    # so the last chunk does too, and the last sample's held u comes from it
    whole, chunked = in_chunks(lambda: simulate_closed_loop(r=Sine(0.05, 1.5), ts=0.01, dt=0.0025, t_end=0.8275,
                                                            controller=controller, u_limit=4.0,
                                                            d=WhiteNoise(3e3, seed=2, hold_s=0.0025)),
                               0.8275, 0.0025, 0.01)
    for run in chunked:
        same(whole, run)


def test_a_run_that_fails_reports_the_same_step_in_chunks(in_chunks):
    # an absurd bulk modulus on the linearised model puts a pole far outside the stability region of
    # the fixed-step RK4 (an input given as a function of t takes it): the run diverges after 39 ms,
    # and the failure is reported at its global step whatever chunk it happens in. (The adaptive
    # integrator follows that pole with small steps and does not fail.)
    p = ActuatorParams(beta_e=1e14)
    whole, chunked = in_chunks(lambda: simulate(p, u=_sine_fn, t_end=0.5, model="linear"), 0.5, 1e-3)
    assert not whole.success and "t = 0.039 s" in whole.message
    for run in chunked:
        same(whole, run)


@pytest.mark.parametrize("parallel", [True, False])
def test_a_batch_with_a_failing_run_in_chunks(in_chunks, parallel):
    # the failed run is left alone, the others go on to the end
    params = [ActuatorParams(), ActuatorParams(beta_e=1e14), ActuatorParams(M=900.0)]
    us = [_sine_fn] * 3                             # a function of t: the fixed-step RK4, in chunks
    whole, chunked = in_chunks(lambda: simulate_many(params, us, t_end=0.5, model="linear", parallel=parallel),
                               0.5, 1e-3)
    assert [r.success for r in whole] == [True, False, True]
    for runs in chunked:
        for a, b in zip(whole, runs, strict=True):
            same(a, b)


def test_the_default_chunks_give_the_same_bits_as_one():
    # 500 000 steps: ten chunks of the real size
    r = np.sin(np.arange(501) * 0.05) * 0.02
    one = sim.CHUNK_STEPS
    try:
        sim.CHUNK_STEPS = 10**9
        whole = simulate_closed_loop(r=r, ts=0.5, d=WhiteNoise(1e3, seed=4, hold_s=0.5))
    finally:
        sim.CHUNK_STEPS = one
    assert round(250.0 / sim.DEFAULT_H_MAX) >= 10 * sim.CHUNK_STEPS
    same(whole, simulate_closed_loop(r=r, ts=0.5, d=WhiteNoise(1e3, seed=4, hold_s=0.5)))


# -- memory ---------------------------------------------------------------------

def test_memory_follows_the_output_not_the_steps():
    # 4000 samples at Ts = 0.5 s (the heaviest frequency experiment's size class):
    # 2000 s of closed loop, 4 M steps. One (n_steps, 3) float array of stage
    # samples would take 96 MB; the run before chunking took 2 of them and more
    r = np.sin(np.arange(4001) * 0.01) * 0.01
    steps = 4000 * round(0.5 / sim.DEFAULT_H_MAX)
    simulate_closed_loop(r=r[:5], ts=0.5)          # load the kernel outside the measurement
    peak, res = peak_bytes(lambda: simulate_closed_loop(r=r, ts=0.5, kp=10.0))
    assert res.success and res.t.size == 4001
    one_stage_array = steps * 3 * 8
    print(f"\npeak {peak / 2**20:.1f} MB for {steps} steps; one stage array {one_stage_array / 2**20:.0f} MB")
    assert peak < one_stage_array / 10, f"peak {peak / 2**20:.1f} MB"
    est = simulation_cost(2000.0, 0.5, ts=0.5)
    assert est.steps == steps
    assert 0.5 < est.peak_bytes / peak < 2.0, (est.peak_bytes, peak)


def test_white_noise_late_in_a_long_stream_is_cheap_and_the_same():
    # the simulator asks for noise one chunk at a time: a window late in the
    # stream must not redraw (and hold) the whole stream up to it
    w = WhiteNoise(1.0, seed=7, hold_s=1e-4)
    t = 400.0 + np.arange(1000) * 1e-4                   # draws 4 000 000 .. 4 000 999
    cold, vals = peak_bytes(lambda: w(t))
    warm, again = peak_bytes(lambda: w(t))
    reference = np.random.default_rng(7).standard_normal(4_001_000)[4_000_000:]
    np.testing.assert_array_equal(vals, reference)
    np.testing.assert_array_equal(again, reference)
    assert cold < 4_000_000 * 8 / 10, cold              # the whole stream: 32 MB
    assert warm < 1_000_000, warm                        # from the kept generator state
    # any window, in any order, gives the draws of one call from the start
    t_all = np.arange(0.0, 20.0, 1e-3 / 3)
    whole = WhiteNoise(1.0, seed=7, hold_s=1e-3)(t_all)
    pieces = WhiteNoise(1.0, seed=7, hold_s=1e-3)
    halves = [pieces(t_all[30000:]), pieces(t_all[:30000])]
    np.testing.assert_array_equal(np.concatenate(halves[::-1]), whole)


@pytest.mark.parametrize("t_end, dt, n_runs, parallel", [(5.0, 1e-3, 4, True), (5.0, 1e-3, 4, False),
                                                         (60.0, 1e-3, 2, True), (400.0, 1e-2, 1, True)])
def test_cost_estimate_is_within_a_factor_two_of_the_measured_peak(t_end, dt, n_runs, parallel):
    us = [Sine(2.0 + k, 2.0) for k in range(n_runs)]
    ds = [WhiteNoise(100.0, seed=k, hold_s=dt) for k in range(n_runs)]
    simulate_many(None, us[:1], t_end=0.1)
    peak, _ = peak_bytes(lambda: simulate_many(None, us, ds, t_end=t_end, dt=dt, parallel=parallel))
    est = simulation_cost(t_end, dt, n_runs=n_runs, parallel=parallel)
    assert est.steps == n_runs * round(t_end / sim.DEFAULT_H_MAX)
    assert 0.5 < est.peak_bytes / peak < 2.0, (est.peak_bytes, peak)


def test_cost_estimates_count_steps_samples_and_time():
    cfg = FrequencyExperiment(n_samples=20000, ts=0.5)
    cost = cfg.cost()
    assert cost.steps == 2 * 19999 * round(0.5 / sim.DEFAULT_H_MAX)
    assert cost.output_samples == 2 * 20000
    small = FrequencyExperiment().cost()
    assert small.steps == 2 * 999 * round(0.01 / sim.DEFAULT_H_MAX)
    assert cost.peak_bytes > small.peak_bytes
    # the estimation's time counts: more than the steps alone
    assert cost.seconds_estimate > cost.steps / cost.STEPS_PER_SECOND
    assert lse_cost(20.0).steps == 4 * lse_cost(5.0).steps
    assert lse_cost(5.0, resimulation=True).steps == 2 * lse_cost(5.0).steps
    assert lse_cost(5.0, estimator="iv").steps == 6 * lse_cost(5.0).steps     # at most 5 auxiliary simulations
    both = simulation_cost(5.0, 1e-3) + simulation_cost(10.0, 1e-3)
    assert both.steps == 30000 and both.peak_bytes == simulation_cost(10.0, 1e-3).peak_bytes
    with pytest.raises(ValueError, match=r"n_runs = 0 is not allowed: must be"):
        simulation_cost(5.0, 1e-3, n_runs=0)
    with pytest.raises(ValueError, match="is not allowed"):
        simulation_cost(1e5, 1e-3)                       # beyond MAX_STEPS, as the simulation would say


@pytest.mark.parametrize("n_samples, ts", [(1000, 0.01), (4000, 0.01), (1000, 0.2)])
def test_frequency_experiment_memory_estimate_is_within_a_factor_two(n_samples, ts):
    cfg = FrequencyExperiment(n_samples=n_samples, ts=ts)
    run_frequency_identification(config=FrequencyExperiment(n_samples=200, signal_type="rgs"))   # imports: unmeasured
    peak, _ = peak_bytes(lambda: run_frequency_identification(config=cfg))
    assert 0.5 < cfg.cost().peak_bytes / peak < 2.0, (cfg.cost().peak_bytes, peak)


@pytest.mark.parametrize("t_end, model, estimator", [(5.0, "constant", "ls"), (20.0, "harmonic", "ls"),
                                                     (5.0, "constant", "iv"), (20.0, "harmonic", "iv")])
def test_least_squares_memory_estimate_is_within_a_factor_two(t_end, model, estimator):
    peak, _ = peak_bytes(lambda: run_lse(None, "sine:5000", disturbance_model=model, t_end=t_end,
                                         estimator=estimator))
    cost = lse_cost(t_end, estimator=estimator)
    assert 0.5 < cost.peak_bytes / peak < 2.0, (cost.peak_bytes, peak)


# -- cancellation ------------------------------------------------------------------

def cancel_after(token, seconds):
    timer = threading.Timer(seconds, token.cancel, args=("test",))
    timer.start()
    return timer


class RecordingToken(CancelToken):
    """Never cancelled; records which functions checked it."""

    def __init__(self):
        super().__init__()
        self.callers = set()

    def check(self):
        frame = sys._getframe(1)
        # eha_core.cancel.check(token) forwards: record its caller
        if frame.f_code.co_name == "check":
            frame = frame.f_back
        self.callers.add(frame.f_code.co_name)
        super().check()


def test_the_token_is_thread_safe_and_keeps_the_first_reason():
    token = CancelToken()
    assert not token.cancelled and token.reason == ""
    token.check()
    threads = [threading.Thread(target=token.cancel, args=(f"reason {k}",)) for k in range(8)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert token.cancelled and token.reason.startswith("reason ")
    first = token.reason
    token.cancel("later")
    with pytest.raises(Cancelled, match=first):
        token.check()
    assert token.reason == first
    unnamed = CancelToken()
    unnamed.cancel()
    assert unnamed.reason == "cancelled"


def _cancel_latency(run):
    """(latency, full): how long ``run(token)`` goes on after a cancel set from another thread at 40 % of
    its uncancelled wall time ``full`` (measured first) [s]."""
    t0 = time.perf_counter()
    run(None)
    full = time.perf_counter() - t0
    token = CancelToken()
    at = 0.4 * full
    timer = cancel_after(token, at)
    t0 = time.perf_counter()
    with pytest.raises(Cancelled, match="test"):
        run(token)
    stopped = time.perf_counter() - t0
    timer.join()
    return stopped - at, full


# the bulk modulus raised 10^3 and 10^7 times: the pressures' poles (eq. 4) make the adaptive integrator
# take 700 and 60 000 steps per simulated second, so that a run lasts long enough to cancel it in its middle
STIFF_CASES = {
    "many chunks": (ActuatorParams(beta_e=1e12), 1000.0),        # 100 chunks of 10 s, 0.7 M steps
    "one stiff chunk": (ActuatorParams(beta_e=1e16), 10.0),      # one chunk, 0.6 M steps
}


@pytest.mark.parametrize("case", list(STIFF_CASES))
def test_a_long_closed_loop_stops_soon_after_cancel(case):
    # the adaptive kernel pauses every CANCEL_CHECK_STEPS steps for the check (about 5 ms of work),
    # whatever a simulated second costs: a chunk of 10 simulated seconds can be 10^5 steps and more
    params, t_end = STIFF_CASES[case]
    r = np.sin(np.arange(round(t_end / 0.5) + 1) * 0.01) * 0.01
    simulate_closed_loop(params, r=r[:5], ts=0.5)          # load the kernel outside the measurement
    latency, full = _cancel_latency(lambda tok: simulate_closed_loop(params, r=r, ts=0.5, cancel=tok))
    print(f"\n{case}: uncancelled {full:.3f} s, stopped {1e3 * latency:.1f} ms after the cancel")
    assert latency < 0.05 * full, (latency, full)


def test_the_frequency_identification_stops_soon_after_cancel():
    # both simulations (2 x 4 M steps) and tfest take a good share of the time
    cfg = FrequencyExperiment(n_samples=4000, ts=0.5)
    # compile and import outside the measurement: a cold first run took 9 s, a warm one 5 s, and a cancel
    # at half the cold time came after the warm run's end
    run_frequency_identification(config=FrequencyExperiment(n_samples=200, signal_type="rgs"))
    t0 = time.perf_counter()
    run_frequency_identification(config=cfg)
    full = time.perf_counter() - t0
    for at in (0.05, 0.5 * full):                          # in the first simulation, then later on
        token = CancelToken()
        cancel_after(token, at)
        t0 = time.perf_counter()
        with pytest.raises(Cancelled):
            run_frequency_identification(config=cfg, cancel=token)
        stopped = time.perf_counter() - t0
        print(f"\nuncancelled {full:.2f} s, cancelled at {at:.2f} s, stopped after {stopped:.2f} s")
        assert stopped - at < 0.25 * full, (at, stopped, full)


def test_cancel_reaches_every_stage_of_the_frequency_identification():
    token = RecordingToken()
    run_frequency_identification(config=FrequencyExperiment(n_samples=1000), cancel=token)
    assert {"_adaptive_runs", "srivc", "evaluate", "run_frequency_identification"} <= token.callers


def test_cancel_reaches_the_least_squares_estimation():
    token = RecordingToken()
    run_lse(None, "sine:5000", disturbance_model="harmonic", cancel=token)
    assert {"_adaptive_runs", "identify_lse", "_newey_west", "f", "rss"} <= token.callers


def test_cancel_reaches_every_iv_iteration_and_its_auxiliary_simulation():
    data = lse_data(disturbance="white:1000", t_end=1.0)
    token = RecordingToken()
    identify_lse(data, estimator="iv", cancel=token)
    # _adaptive_runs: the simulation of the instruments (the data were simulated without the token)
    assert {"_adaptive_runs", "identify_lse", "_iv", "f"} <= token.callers


def _square_wave_data():
    ts = 0.01
    u = np.sign(np.sin(2 * np.pi * 0.5 * ts * np.arange(4000)))
    y = simulate_tf([20.0], [1.0, 6.0, 20.0], u, ts) + 0.01 * np.random.default_rng(0).standard_normal(4000)
    return u, y, ts


@pytest.mark.parametrize("stage", ["srivc", "oe"])
def test_a_cancel_in_tfest_lands_within_one_evaluation(monkeypatch, stage):
    # the token is set from inside the k-th evaluation (as another thread
    # would, at any moment): the estimator stops at the next evaluation or the
    # next SRIVC iteration, doing no more than one more simulation
    u, y, ts = _square_wave_data()
    token = CancelToken()
    calls = {"evaluate": 0, "filter": 0}
    evaluate, apply = oe_criterion.OutputError.evaluate, srivc_mod.StateVariableFilter.apply

    def counted_evaluate(self, *args, **kwargs):
        calls["evaluate"] += 1
        out = evaluate(self, *args, **kwargs)
        if calls["evaluate"] == 3:
            token.cancel("test")           # while the third evaluation ran
        return out

    def counted_apply(self, *args, **kwargs):
        calls["filter"] += int(token.cancelled)
        return apply(self, *args, **kwargs)

    monkeypatch.setattr(oe_criterion.OutputError, "evaluate", counted_evaluate)
    monkeypatch.setattr(srivc_mod.StateVariableFilter, "apply", counted_apply)
    with pytest.raises(Cancelled, match="test"):
        if stage == "srivc":
            tfest(u, y, ts, n_poles=2, cancel=token)
        else:
            oe_fit(u, y, ts, [15.0], [1.0, 5.0, 15.0], cancel=token)
    # the evaluation running when the token was set finishes; the next one (if
    # any) stops at its check, and no SRIVC iteration filters the data again
    assert calls["evaluate"] in (3, 4)
    assert calls["filter"] == 0


def test_tfest_stops_soon_after_cancel_from_another_thread():
    cfg = FrequencyExperiment(n_samples=4000, ts=0.5)
    data = cfg.closed_loop(ActuatorParams(), cfg.excitation())
    kwargs = {"initial_condition": cfg.initial_condition, "input_offset": cfg.input_offset}
    t0 = time.perf_counter()
    tfest(data.r, data.x, cfg.ts, 3, 0, **kwargs)
    full = time.perf_counter() - t0
    token = CancelToken()
    cancel_after(token, 0.05)
    t0 = time.perf_counter()
    with pytest.raises(Cancelled):
        tfest(data.r, data.x, cfg.ts, 3, 0, cancel=token, **kwargs)
    stopped = time.perf_counter() - t0
    print(f"\ntfest uncancelled {full:.3f} s, stopped after {stopped:.3f} s")
    assert stopped < 0.5 * full, (stopped, full)


def _lse_resimulation_call(token):
    data = lse_data(t_end=1.0)
    return lse_resimulation(identify_lse(data), ActuatorParams(), data, cancel=token)


@pytest.mark.parametrize("call", [
    lambda tok: simulate(u=Sine(1.0, 1.0), t_end=1.0, cancel=tok),
    lambda tok: simulate_many(None, [Sine(1.0, 1.0)] * 2, t_end=1.0, cancel=tok),
    lambda tok: simulate_closed_loop(r=R83, ts=0.01, cancel=tok),
    lambda tok: run_paper_cases(t_end=1.0, cancel=tok),
    lambda tok: lse_simulation(t_end=1.0, cancel=tok),
    lambda tok: lse_data(t_end=1.0, cancel=tok),
    lambda tok: run_lse(t_end=1.0, cancel=tok),
    _lse_resimulation_call,
    lambda tok: run_lse_table(t_end=1.0, cancel=tok),
    lambda tok: identify_lse(lse_data(t_end=1.0), cancel=tok),
    lambda tok: identify_lse(lse_data(t_end=1.0), estimator="iv", cancel=tok),
    lambda tok: run_frequency_identification(config=FrequencyExperiment(n_samples=1000), cancel=tok),
    lambda tok: tfest(*_square_wave_data(), n_poles=2, cancel=tok),
    lambda tok: oe_fit(*_square_wave_data(), [20.0], [1.0, 6.0, 20.0], cancel=tok),
], ids=["simulate", "simulate_many", "simulate_closed_loop", "run_paper_cases", "lse_simulation", "lse_data",
        "run_lse", "lse_resimulation", "run_lse_table", "identify_lse", "identify_lse_iv",
        "run_frequency_identification", "tfest",
        "oe_fit"])
def test_a_cancelled_token_stops_every_long_computation(call):
    token = CancelToken()
    token.cancel("the page was closed")
    with pytest.raises(Cancelled, match="the page was closed"):
        call(token)
    assert call(None) is not None                       # and without a token, it runs as before
