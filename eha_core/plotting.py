"""Matplotlib figures of the core's results, for a Python prompt or a notebook.

The results' ``plot()`` methods delegate here (as python-control's
``TimeResponseData.plot`` delegates to ``timeplot``): each function draws what
the result already holds, computes no physics, and returns the
:class:`matplotlib.figure.Figure` (its axes are ``fig.axes``). Signals are drawn
in the units a user reads (mm, mm/s, MPa, V, kN).

matplotlib comes with python-control (a dependency) but the core does not
need it to import: it is imported when a figure is drawn, and where it is
missing a plot raises :class:`ImportError` saying ``pip install matplotlib``.
Importing this module imports neither matplotlib nor anything of the app. docs/python.md
shows each route's figure; tests/core/test_results_api.py draws them.
"""

from __future__ import annotations

import numpy as np

from ._checks import not_allowed
from ._display import SIGNAL_DISPLAY

__all__ = ["plot_simulation", "plot_lse", "plot_bode", "plot_frequency_identification", "plot_greybox",
           "MATPLOTLIB_MISSING"]

#: What a plot says when matplotlib is not installed.
MATPLOTLIB_MISSING = "drawing a result needs matplotlib, which is not installed: pip install matplotlib"


def _pyplot():
    try:
        import matplotlib.pyplot as plt
    except ImportError as exc:
        raise ImportError(MATPLOTLIB_MISSING) from exc
    return plt


def _figure(n_rows: int, title: str):
    plt = _pyplot()
    fig, axes = plt.subplots(n_rows, 1, sharex=True, squeeze=False, figsize=(8.0, 1.6 + 1.8 * n_rows),
                             layout="constrained")
    fig.suptitle(title)
    return fig, list(axes[:, 0])


def _shown(name: str, values) -> np.ndarray:
    return np.asarray(values, dtype=float) / SIGNAL_DISPLAY[name][2]


def _label(quantity: str, name: str) -> str:
    return f"{quantity} [{SIGNAL_DISPLAY[name][1]}]"


def plot_simulation(res):
    """The states and inputs of a run against time: x (and the reference r), v, p1 and p2, u, and the load d
    when there is one.

    Parameters
    ----------
    res : eha_core.simulate.SimulationResult
        The run.
    """
    loaded = bool(np.any(np.asarray(res.d) != 0))
    title = res.label or f"{res.model}, {res.controller}"
    fig, axes = _figure(5 if loaded else 4, title if res.success else f"{title} (FAILED: {res.message})")
    ax = axes[0]
    ax.plot(res.t, _shown("x", res.x), label="x")
    if res.r is not None:
        ax.plot(res.t, _shown("r", res.r), "--", label="r")
        ax.legend(loc="upper right")
    ax.set_ylabel(_label("x", "x"))
    axes[1].plot(res.t, _shown("v", res.v))
    axes[1].set_ylabel(_label("v", "v"))
    axes[2].plot(res.t, _shown("p1", res.p1), label="p1")
    axes[2].plot(res.t, _shown("p2", res.p2), label="p2")
    axes[2].set_ylabel(_label("p", "p1"))
    axes[2].legend(loc="upper right")
    axes[3].plot(res.t, _shown("u", res.u))
    axes[3].set_ylabel(_label("u", "u"))
    if loaded:
        axes[4].plot(res.t, _shown("d", res.d))
        axes[4].set_ylabel(_label("d", "d"))
    axes[-1].set_xlabel("t [s]")
    return fig


def plot_lse(res):
    """The least squares' two filtered equations (eqs. 15a, 15b after the prefilter of eq. 17): each
    measured side and the estimate's fit, against time.

    Parameters
    ----------
    res : eha_core.identify.lse.LSEResult
        The estimate (with its signals ``t``, ``y1f``, ``y1_fit``, ``y2f``, ``y2_fit``).
    """
    from ._display import short

    title = f"least squares ({res.estimator})" + ("" if res.success else f": FAILED ({short(res.message, 80)})")
    fig, (ax1, ax2) = _figure(2, title)
    ax1.plot(res.t, np.asarray(res.y1f) / 1e3, label="measured, filtered")
    ax1.plot(res.t, np.asarray(res.y1_fit) / 1e3, "--", label="fit")
    ax1.set_ylabel("A1 p1 - A2 p2 [kN]")
    ax1.legend(loc="upper right")
    ax2.plot(res.t, np.asarray(res.y2f) / 1e6, label="measured, filtered")
    ax2.plot(res.t, np.asarray(res.y2_fit) / 1e6, "--", label="fit")
    ax2.set_ylabel("dp1/dt [MPa/s]")
    ax2.set_xlabel("t [s]")
    return fig


def _bode_axes(title: str):
    fig, (mag, phase) = _figure(2, title)
    mag.set_ylabel("magnitude [dB]")
    phase.set_ylabel("phase [deg]")
    phase.set_xlabel("ω [rad/s]")
    for ax in (mag, phase):
        ax.set_xscale("log")
        ax.grid(True, which="both", alpha=0.3)
    return fig, mag, phase


def plot_bode(estimate, w=None):
    """The Bode diagram of an estimated transfer function (its input delay included).

    Parameters
    ----------
    estimate : eha_core.identify.tfresult.TFEstimate
        The estimate.
    w : array_like, optional
        Frequencies [rad/s]; default 400 from 0.01 rad/s to the Nyquist frequency pi / ts.
    """
    w = np.logspace(-2, np.log10(np.pi / estimate.ts), 400) if w is None else np.asarray(w, dtype=float)
    resp = estimate.frequency_response(w)
    title = f"estimate: {estimate.n_poles} poles, {estimate.n_zeros} zeros, fit {estimate.fit_percent:.1f} %"
    fig, mag, phase = _bode_axes(title if estimate.success else f"{title} (FAILED)")
    mag.plot(resp.w, resp.magnitude_db)
    phase.plot(resp.w, resp.phase_deg)
    return fig


def plot_frequency_identification(result):
    """Fig. 12: the estimate's Bode diagram beside the linearised H(s) of eq. 24 and the data's own
    frequency response (ETFE or spectral estimate, with its band).

    Parameters
    ----------
    result : eha_core.experiments.FrequencyIdentification
        The experiment; without its Bode data (a failed estimate) the estimate's diagram alone is drawn.
    """
    b = result.bode
    if b is None:
        return plot_bode(result.estimate)
    fig, mag, phase = _bode_axes(f"H(s): fit {result.estimate.fit_percent:.1f} %"
                                 + ("" if result.success else " (FAILED)"))
    mag.plot(b.w, b.estimate.magnitude_db, label="estimate")
    phase.plot(b.w, b.estimate.phase_deg, label="estimate")
    if b.theoretical is not None:
        mag.plot(b.w, b.theoretical.magnitude_db, "--", label="linearised (eq. 24)")
        phase.plot(b.w, b.theoretical.phase_deg, "--", label="linearised (eq. 24)")
    mag.plot(b.data_w, b.data_magnitude_db, ".", label=f"data ({b.data_method})")
    phase.plot(b.data_w, b.data_phase_deg, ".", label=f"data ({b.data_method})")
    if b.data_lower_db is not None and b.data_upper_db is not None:
        mag.fill_between(b.data_w, b.data_lower_db, b.data_upper_db, alpha=0.2, label="data's band")
    mag.legend(loc="lower left")
    return fig


def plot_greybox(res):
    """Each measured signal against the estimated model's simulation of it.

    Parameters
    ----------
    res : eha_core.identify.greybox.GreyBoxResult
        The estimate, with the record it was made from (``res.data``).
    """
    from .identify.greybox import GREYBOX_SIGNALS

    if res.data is None:
        raise not_allowed("res.data", None, "the estimate does not hold its record: nothing to draw")
    title = "grey-box estimate" + ("" if res.success else " (FAILED: see res.message)")
    fig, axes = _figure(len(res.measured), title)
    t = res.data.t
    for ax, name in zip(axes, res.measured, strict=True):
        ax.plot(t, _shown(name, res.data.signals[name]), label="measured")
        ax.plot(t, _shown(name, res.simulated[:, GREYBOX_SIGNALS.index(name)]), "--",
                label=f"model, fit {res.fit[name]:.1f} %")
        ax.set_ylabel(_label(name, name))
        ax.legend(loc="upper right")
    axes[-1].set_xlabel("t [s]")
    return fig
