"""The paper's results, recomputed: one typed result behind ``eha reproduce``'s report.

:func:`reproduce` runs everything the paper shows (Tables 1-4, Figs. 2-13 and
eqs. 23-27) for a parameter set and returns a :class:`Reproduction`: every
run, estimate and number of the report, with the parameters they were
computed for. The app renders it (:mod:`eha_app.render.report`); nothing there
computes physics. :meth:`Reproduction.numbers` is the report's
``results.json``.

Examples
--------
>>> from eha_core.reproduction import reproduce
>>> r = reproduce()                                   # doctest: +SKIP
>>> round(r.numbers()["fit_percent"], 1)              # doctest: +SKIP
95.2
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .cancel import CancelToken, check
from .experiments import (
    LSE_INPUT_RICH,
    LSE_INPUT_RICH_T_END,
    PAPER_EQ25,
    PAPER_EQ26,
    PAPER_FIT_PERCENT,
    PAPER_TABLE4,
    FrequencyExperiment,
    FrequencyIdentification,
    lse_data,
    run_frequency_identification,
    run_lse,
    run_lse_table,
    run_paper_cases,
)
from .linear import LinearModel, linearize
from .params import ActuatorParams
from .simulate import SimulationResult

if TYPE_CHECKING:
    from .identify.lse import LSEResult
    from .identify.tfest import TFEstimate

__all__ = ["ReproductionSettings", "L0Row", "CaseDifference", "Reproduction", "reproduce", "REPRODUCTION_STEPS",
           "STATES"]

#: (field, display unit, scale from SI) of the four states, as the figures show them.
STATES = (("x", "mm", 1e3), ("v", "mm/s", 1e3), ("p1", "MPa", 1e-6), ("p2", "MPa", 1e-6))
#: The steps :func:`reproduce` reports progress for, in order.
REPRODUCTION_STEPS = ("parameters (Tables 1-2)", "open-loop simulations (Figs. 2-7)",
                      "least squares (Tables 3-4, both disturbance models)",
                      "closed-loop experiment and transfer-function estimation (Figs. 8-13)",
                      "grey-box identification (the three routes side by side)")
#: The chamber lengths tried when inferring L0 from eq. 23 (the paper does not print it).
L0_TRIED = (0.2, 0.25, 0.3, 0.35, 0.4)


@dataclass(frozen=True)
class ReproductionSettings:
    """What to compute: the seed of every random signal, and the paper's record
    lengths (5 s open loop, 5 s of least-squares data, 1000 samples at Ts =
    0.01 s closed loop). The computation takes about 1 s; shorter records
    would save little of a report's time, most of which is drawing."""

    seed: int = 0
    case_t_end: float = 5.0
    lse_t_end: float = 5.0
    freq_samples: int = 1000


@dataclass(frozen=True)
class L0Row:
    """eq. 23 for one chamber length: its s coefficient and gain."""

    L0: float
    s_coefficient: float
    gain: float


@dataclass(frozen=True)
class CaseDifference:
    """Nonlinear against linearised for one case and state (Figs. 4-7), display units."""

    case: str
    state: str
    unit: str
    rms: float
    max: float


@dataclass(frozen=True, eq=False)
class Reproduction:
    """Everything the report shows, for ``params`` (see the module docstring).

    ``lse`` maps a disturbance model ('constant', 'harmonic') to Table 4's
    scenarios and their estimates; ``lse_rich`` is the white-noise scenario
    under the richer excitation; ``lse_linear_interpolation`` the d = 0
    scenario with the classical (linear) discretisation of the regressors;
    ``frequency_plain`` the transfer function with the paper's bare structure
    (zero initial state, no offset); ``frequency_linear_model`` the same
    experiment around the linearised model.
    """

    settings: ReproductionSettings
    params: ActuatorParams
    linear: LinearModel
    l0_inference: tuple[L0Row, ...]
    cases_nonlinear: tuple[SimulationResult, ...]
    cases_linear: tuple[SimulationResult, ...]
    case_differences: tuple[CaseDifference, ...]
    lse: dict
    lse_rich: LSEResult
    lse_linear_interpolation: LSEResult
    lse_peak_viscous_force: float
    frequency: FrequencyIdentification
    frequency_plain: TFEstimate
    frequency_linear_model: FrequencyIdentification
    paper_eq26_from_eq25: tuple[np.ndarray, np.ndarray]
    greybox: object = None          # GreyBoxResult on Table 3's record (x, p1, p2), from the paper's values

    def __repr__(self) -> str:
        from ._display import short

        lse = ", ".join(f"{model} ({len(scenarios)} scenarios)" for model, scenarios in self.lse.items())
        failed = [name for name, res in (("frequency", self.frequency), ("frequency_plain", self.frequency_plain),
                                         ("lse_rich", self.lse_rich), ("greybox", self.greybox))
                  if res is not None and not res.success]
        failed += [f"lse[{m}][{s}]" for m, scenarios in self.lse.items() for s, r in scenarios.items() if not r.success]
        state = "every estimate succeeded" if not failed else "FAILED: " + short(", ".join(failed), 200)
        return (f"Reproduction: the paper's cases, tables and figures (seed {self.settings.seed}): {state}\n"
                f"  .cases_nonlinear, .cases_linear: {len(self.cases_nonlinear)} cases each; .lse: {lse}; "
                f".frequency: {self.frequency.estimate.n_poles} poles, fit {self.frequency.estimate.fit_percent:.2f} %"
                f"\n  .greybox, .numbers(): every number of the report; .table_rows(): Tables 3-4")

    def table_rows(self) -> list[dict]:
        """Tables 3-4 as rows: model, scenario, parameter, nominal, estimate, interval, paper."""
        rows = []
        for model, scenarios in self.lse.items():
            for scen, res in scenarios.items():
                for k, v in res.estimates.items():
                    lo, hi = res.ci95[k]
                    rows.append({"model": model, "scenario": scen, "parameter": k, "nominal": res.nominal.get(k),
                                 "estimate": v, "std_error": res.std_errors[k], "ci95_lo": lo, "ci95_hi": hi,
                                 "rel_error": res.rel_error.get(k), "paper": PAPER_TABLE4[scen].get(k)})
        return rows

    def numbers(self) -> dict:
        """Every number of the report, JSON-ready (the report's ``results.json``)."""
        p, fi, lin = self.params, self.frequency, self.linear
        e = fi.estimate
        none_c = self.lse["constant"]["none"]
        c5, h5 = self.lse["constant"]["5000 sin"], self.lse["harmonic"]["5000 sin"]
        wn = self.lse["constant"]["white noise"]
        cases_li = {r.label: r for r in self.cases_linear}
        cases_nl = {r.label: r for r in self.cases_nonlinear}
        out = {
            "seed": self.settings.seed,
            "params": p.to_dict(), "p2_init": p.p2_init,
            "l0_inference": [dataclasses.asdict(row) for row in self.l0_inference],
            "differences": [dataclasses.asdict(d) for d in self.case_differences],
            "linear_p2_max_mpa": float(cases_li["Case 3"].p2.max() / 1e6),
            "nonlinear_p2_range_mpa": [float(cases_nl["Case 3"].p2.min() / 1e6),
                                       float(cases_nl["Case 3"].p2.max() / 1e6)],
            "least_squares": self.table_rows(),
            "table3_beta_e": none_c.estimates["beta_e"],
            "table3_beta_e_rel_error": none_c.rel_error["beta_e"],
            "b_5000_constant": {"estimate": c5.estimates["B"], "rel_error": c5.rel_error["B"],
                                "ci95": list(c5.ci95["B"])},
            "b_5000_constant_covers": bool(c5.covers("B")),
            "b_5000_harmonic": {"estimate": h5.estimates["B"], "rel_error": h5.rel_error["B"]},
            "harmonic_freq_hz": h5.disturbance_freq_hz,
            "b_white_constant": {"estimate": wn.estimates["B"], "rel_error": wn.rel_error["B"],
                                 "std_error": wn.std_errors["B"]},
            "b_se_default": wn.std_errors["B"], "b_se_rich": self.lse_rich.std_errors["B"],
            "b_linear_interpolation_rel_error": self.lse_linear_interpolation.rel_error["B"],
            "beta_e_linear_interpolation_rel_error": self.lse_linear_interpolation.rel_error["beta_e"],
            "b_none_rel_error": none_c.rel_error["B"],
            "b_times_vmax_lse": self.lse_peak_viscous_force,
            "hhat_num": [float(c) for c in e.num], "hhat_den": [float(c) for c in e.den],
            "hhat_param_std": None if e.param_std is None else [float(v) for v in e.param_std],
            "fit_percent": float(e.fit_percent), "initial_condition": e.initial_condition,
            "input_offset": None if e.input_offset is None else float(e.input_offset),
            "validation_fit_percent": float(fi.validation.fit_percent) if fi.validation else float("nan"),
            "fit_percent_plain": float(self.frequency_plain.fit_percent),
            "linear_plant_a1": float(self.frequency_linear_model.estimate.den[1]),
            "theoretical_num": [float(c) for c in fi.theoretical[0]],
            "theoretical_den": [float(c) for c in fi.theoretical[1]],
            "vmax_mm_s": fi.peak_speed * 1e3, "inv_kf_mm_s": 1e3 / p.k_f, "ps_mpa": p.ps / 1e6,
            "gain_positive": lin.gain("positive"), "gain_negative": lin.gain("negative"),
            "paper_eq26_from_eq25": [[float(c) for c in a] for a in self.paper_eq26_from_eq25],
            "paper_eq25": {"num": list(PAPER_EQ25[0]), "den": list(PAPER_EQ25[1]), "fit_percent": PAPER_FIT_PERCENT},
            "paper_eq26": {"num": list(PAPER_EQ26[0]), "den": list(PAPER_EQ26[1])},
        }
        if fi.open_loop is not None:
            out["phat_num"] = [float(c) for c in fi.open_loop[0]]
            out["phat_den"] = [float(c) for c in fi.open_loop[1]]
        if fi.backout is not None:
            out["backout"] = fi.backout.to_dict()
            out["beta_e_gain"] = fi.backout.beta_e_from_gain
            out["beta_e_stiffness"] = fi.backout.beta_e_from_stiffness
        return out


def _case_differences(nonlinear, linear) -> tuple[CaseDifference, ...]:
    rows = []
    for a, b in zip(nonlinear, linear, strict=True):
        for name, unit, scale in STATES:
            d = (getattr(a, name) - getattr(b, name)) * scale
            rows.append(CaseDifference(a.label, name, unit, float(np.sqrt(np.mean(d * d))), float(np.max(np.abs(d)))))
    return tuple(rows)


def reproduce(params: ActuatorParams | None = None, *, seed: int = 0,
              progress: Callable[[str], None] | None = None, cancel: CancelToken | None = None) -> Reproduction:
    """Compute everything the paper shows (see the module docstring).

    Parameters
    ----------
    params : ActuatorParams, optional
        The actuator; defaults to the paper's parameters.
    seed : int
        Seed of the least squares' noisy scenarios and of the frequency experiment's excitation.
    progress : callable, optional
        ``progress(step)`` is called at the start of each of :data:`REPRODUCTION_STEPS`.
    cancel : eha_core.cancel.CancelToken, optional
        Reaches every simulation and estimator; raises :class:`~eha_core.cancel.Cancelled` when set.
    """
    from .identify.backout import open_loop_from_closed
    from .identify.lse import identify_lse
    from .identify.tfest import tfest

    settings = ReproductionSettings(seed=seed)
    p = params if params is not None else ActuatorParams()
    step = progress or (lambda _what: None)

    step(REPRODUCTION_STEPS[0])
    lin = linearize(p)
    l0_rows = []
    for L0 in L0_TRIED:
        num, den = linearize(p.replace(L0=L0)).tf_coeffs()
        l0_rows.append(L0Row(L0, float(den[2]), float(num[0])))

    step(REPRODUCTION_STEPS[1])
    nl = tuple(run_paper_cases(p, "nonlinear", t_end=settings.case_t_end, cancel=cancel))
    li = tuple(run_paper_cases(p, "linear", t_end=settings.case_t_end, cancel=cancel))

    step(REPRODUCTION_STEPS[2])
    by_model = {m: run_lse_table(p, disturbance_model=m, seed=seed, t_end=settings.lse_t_end, cancel=cancel)
                for m in ("constant", "harmonic")}
    rich = run_lse(p, "white:1000", seed=seed, u=LSE_INPUT_RICH,
                   t_end=settings.lse_t_end * LSE_INPUT_RICH_T_END / 5.0, cancel=cancel)
    data_none = lse_data(p, "none", t_end=settings.lse_t_end, seed=seed, cancel=cancel)
    classical = identify_lse(data_none, p, interpolation="linear")

    step(REPRODUCTION_STEPS[3])
    cfg = FrequencyExperiment(seed=seed, n_samples=settings.freq_samples)
    fi = run_frequency_identification(p, cfg, cancel=cancel)
    check(cancel)
    plain = tfest(fi.data.r, fi.data.x, cfg.ts, 3, 0, initial_condition="zero", input_offset="zero",
                  init=fi.theoretical, cancel=cancel)
    lin_fi = run_frequency_identification(p, dataclasses.replace(cfg, model="linear"), cancel=cancel)

    step(REPRODUCTION_STEPS[4])
    from .experiments import LSE_INPUT
    from .identify.greybox import greybox_data, identify_greybox

    # the third route on Table 3's own record: the least squares' sensors, x, p1 and p2 of them
    # Table 3's experiment as a rig records it: the sine sampled at 1 kHz drives the plant, linear between
    # the samples, so the model sees the plant's own input. (Fitted to the record of the continuous sine, a
    # noise-free fit is left with the sampling's own residual, 7e-6 of x's range, B 1.8 % off and no noise to
    # hide it: its checks rightly fail.)
    gb_data = greybox_data(p, LSE_INPUT, t_end=settings.lse_t_end, dt=data_none.t[1] - data_none.t[0],
                           measured=("x", "p1", "p2"))
    gb_data = dataclasses.replace(gb_data, source="Table 3's experiment (d = 0), noise-free, u sampled at 1 kHz")
    greybox = identify_greybox(gb_data, ("M", "B", "Af", "beta_e"), guess=ActuatorParams(), cancel=cancel)
    return Reproduction(
        settings=settings, params=p, linear=lin, l0_inference=tuple(l0_rows), cases_nonlinear=nl, cases_linear=li,
        case_differences=_case_differences(nl, li), lse=by_model, lse_rich=rich,
        lse_linear_interpolation=classical, lse_peak_viscous_force=float(p.B * np.abs(data_none.v).max()),
        frequency=fi, frequency_plain=plain, frequency_linear_model=lin_fi,
        paper_eq26_from_eq25=open_loop_from_closed(*PAPER_EQ25, kp=cfg.kp), greybox=greybox,
    )
