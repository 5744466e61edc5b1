"""Tab 3, black-box models: ARX, ARMAX, OE, BJ, a state-space model (n4sid) or a process model fitted to
a record of the actuator (MATLAB ident's arx/armax/oe/bj/n4sid/procest), judged on other data (compare,
resid), with fixed orders or the orders chosen from a table of candidates (selstruc).

The record is :class:`~eha_core.identify.blackbox_experiment.BlackBoxExperiment`'s: the closed loop
r [mm] -> x [mm] under a P controller, or the open loop u [V] -> x [mm], on tab 1's actuator. Every
number comes from the core, computed in a worker (:func:`compute_blackbox`); the page draws it.

A closed-loop model goes on the model board (its "Put on the model board" button) as the board's
models are: a continuous-time H(s) of the loop r -> x (the zero-order-hold equivalent of the discrete
model; a process model's own G(s)). An open-loop model (u -> x) is not a model of that loop: the
button stays off and says why.
"""

from __future__ import annotations

import html
import time
from dataclasses import dataclass, field

import numpy as np
import panel as pn

from eha_core.board import BoardModel
from eha_core.identify.blackbox_experiment import BlackBoxExperiment
from eha_core.simulate import DEFAULT_H_MAX

from ..render import blackbox as bbr
from ..render.layout import side_by_side
from ..runtime.jobs import JobState
from ..runtime.limits import RunCost
from ..runtime.tasks import on_click, watch
from ..session import GuideStep, KeptWork, ReportPart, RestoreStep, Section, SectionSnapshot, run_off_notice, stale_note
from ..session.form import Field, Form, Group, parse_fields
from ..session.freshness import ResultView

__all__ = ["BlackBoxPanel", "BlackBoxRequest", "BlackBoxOutcome", "BB_FORM", "BB_DEFAULTS", "parse_blackbox",
           "compute_blackbox", "board_model", "ORDER_FIELDS"]

#: Each structure's order fields (the form's names), in MATLAB's order.
ORDER_FIELDS = {"arx": ("bb_na", "bb_nb", "bb_nk"), "armax": ("bb_na", "bb_nb", "bb_nc", "bb_nk"),
                "oe": ("bb_nb", "bb_nf", "bb_nk"), "bj": ("bb_nb", "bb_nc", "bb_nd", "bb_nf", "bb_nk"),
                "ss": ("bb_n",), "process": ("bb_kind",)}
#: The board's short name of each structure's models (the board numbers them: ARX1, ARX2, ...).
BOARD_PREFIX = {"arx": "ARX", "armax": "ARMAX", "oe": "OE", "bj": "BJ", "ss": "SS", "process": "P"}
_ALL_ORDERS = ("bb_na", "bb_nb", "bb_nc", "bb_nd", "bb_nf", "bb_nk", "bb_n", "bb_kind")


def _order(name: str, label: str, lo: int, tip: str) -> Field:
    return Field(name, label, "integer", lo=lo, hi=10 if name != "bb_nk" else 20, short=name[3:], tip=tip)


BB_FORM = (Group("Experiment", (
    Field("bb_loop", "loop", "select", options=(("closed", "closed: r → x under the P controller"),
                                                ("open", "open: valve command u → x")), short="loop",
          tip="closed: the reference r [mm] to the position x [mm] under u = Kp (r − x); open: the valve command "
              "u [V] to x (an integrator: a process model with I describes it)"),
    Field("bb_signal", "excitation", "select", options=(("prbs", "PRBS"), ("rbs", "random binary"),
                                                        ("rgs", "random Gaussian"), ("sine", "sum of sines")),
          short="excitation", tip="as MATLAB's idinput makes it, up to a tenth of the Nyquist frequency"),
    Field("bb_samples", "samples N", "integer", lo=100, hi=20000, short="samples N",
          tip="samples of the estimation record (and of the validation experiment)"),
    Field("bb_ts", "sample time Ts", "number", unit="s", lo=0.001, hi=0.5, short="Ts"),
    Field("bb_kp", "controller gain Kp", "number", unit="V/m", lo=1.0, hi=1000.0, short="Kp",
          tip="closed loop: the paper's 10 V/m is the loop the model board compares models on (its slow pole is "
              "near 10 s: 150 s at 0.1 s show it); a model of another loop is marked there"),
    Field("bb_noise", "position noise σ", "number", unit="mm", lo=0.0, hi=10.0, short="σ x",
          tip="white noise of the position sensor"),
    Field("bb_seed", "seed", "integer", lo=0, hi=10**6, short="seed",
          tip="of the excitation and the noise; the validation experiment uses the next seed after the estimation's"),
    Field("bb_experiments", "experiments merged", "integer", lo=1, hi=5, short="experiments",
          tip="estimation experiments merged into one data set (MATLAB merge), each from its own seed; the "
              "estimators restart at each, and the validation experiment is one more"),
    Field("bb_detrend", "means", "select", options=(("auto", "removed in closed loop, kept in open loop"),
                                                   ("remove", "removed (MATLAB detrend)"), ("keep", "kept")),
          short="means", tip="each experiment's means of input and output removed before estimation: a linear "
                             "model then need not explain the offsets the valve's asymmetry makes. In open loop "
                             "the position integrates: its mean is no operating point (estimate an input offset "
                             "with a process model instead)"),
)), Group("Validation", (
    Field("bb_validation", "validation data", "select", options=(("second experiment", "a second experiment"),
                                                                  ("split", "the record's last part")),
          short="validation data"),
    Field("bb_fraction", "estimation fraction", "number", lo=0.1, hi=0.9, short="estimation fraction",
          tip="the share of the record the model is estimated from; the rest validates it"),
)), Group("Model", (
    Field("bb_structure", "structure", "select", short="structure",
          options=(("arx", "ARX"), ("armax", "ARMAX"), ("oe", "OE (output error)"), ("bj", "BJ (Box-Jenkins)"),
                   ("ss", "state space (n4sid)"), ("process", "process model (procest)"))),
    Field("bb_choose", "orders", "select", options=(("fixed", "fixed orders"),
                                                    ("select", "select orders (a table of candidates)")),
          short="orders"),
    _order("bb_na", "na (poles of A)", 0, "A(q) = 1 + a1 q⁻¹ + … + a_na q⁻ⁿᵃ"),
    _order("bb_nb", "nb (coefficients of B)", 1, "B(q) = b0 + b1 q⁻¹ + …, nb coefficients"),
    _order("bb_nc", "nc (of C)", 1, "the noise model's numerator"),
    _order("bb_nd", "nd (of D)", 1, "the noise model's denominator (BJ)"),
    _order("bb_nf", "nf (poles of F)", 1, "the input's denominator (OE, BJ)"),
    _order("bb_nk", "nk (input delay)", 0, "samples before the input acts"),
    Field("bb_n", "n (states)", "integer", lo=1, hi=10, short="n"),
    Field("bb_kind", "process kind", "select", options=(("P1D", "P1D: K e^(−Td s) / (1 + Tp1 s)"),
                                                        ("P2D", "P2D: two time constants and a delay"),
                                                        ("P1DI", "P1DI: P1D with an integrator"),
                                                        ("P2DI", "P2DI: P2D with an integrator")),
          short="process kind"),
    Field("bb_offset", "input offset", "select", options=(("zero", "none"), ("estimate", "estimated")),
          short="input offset", tip="process models: y = G (u + c) with a constant c estimated (MATLAB's "
                                    "InputOffset): in open loop the cylinder's velocity differs with the valve's "
                                    "sign, which a zero-mean input turns into such an offset"),
    Field("bb_max_order", "highest order", "integer", lo=1, hi=4, short="highest order",
          tip="ARMAX, OE, BJ: the candidates have every polynomial of order 1, 2, … up to this (nk as given)"),
    Field("bb_criterion", "pick by", "select", options=(("validation fit", "validation fit"), ("bic", "BIC"),
                                                        ("aic", "AIC")), short="pick by",
          tip="validation fit: the fewest parameters whose fit on the validation data cannot be told from the "
              "best's; BIC and AIC: the estimation data's criteria"),
    Field("bb_initial", "initial conditions", "select", options=(("zero", "zero"), ("estimate", "estimated")),
          short="initial conditions", tip="of the estimate (ARMAX, OE, BJ, n4sid, process) and of the fits shown"),
    Field("bb_horizon", "fit's horizon", "select", options=(("simulation", "simulation"),
                                                           ("k", "k-step prediction")), short="horizon"),
    Field("bb_k", "k (steps ahead)", "integer", lo=1, hi=1000, short="k"),
)))
BB_DEFAULTS = {"bb_loop": "closed", "bb_signal": "prbs", "bb_samples": "1500", "bb_ts": "0.1", "bb_kp": "10",
               "bb_noise": "0.01", "bb_seed": "0", "bb_validation": "second experiment", "bb_fraction": "0.5",
               "bb_structure": "arx", "bb_choose": "fixed", "bb_na": "2", "bb_nb": "2", "bb_nc": "1", "bb_nd": "1",
               "bb_nf": "2", "bb_nk": "1", "bb_n": "2", "bb_kind": "P1D", "bb_max_order": "3",
               "bb_criterion": "validation fit", "bb_experiments": "1", "bb_detrend": "auto", "bb_offset": "zero",
               "bb_initial": "zero", "bb_horizon": "simulation", "bb_k": "1"}
_FIELDS = {f.name: f for g in BB_FORM for f in g.fields}


def bb_hidden(texts: dict) -> list[str]:
    """The fields the form's choices leave out: Kp in open loop, the fraction unless split, the orders
    the structure does not have (all of them when the orders are selected, but ARMAX/OE/BJ's delay and
    highest order), the criterion unless selecting, k unless predicting."""
    structure = texts.get("bb_structure", "arx")
    select = texts.get("bb_choose") == "select"
    shown = set()
    if select:
        shown |= {"bb_criterion"}
        if structure in ("armax", "oe", "bj"):
            shown |= {"bb_max_order", "bb_nk"}
    else:
        shown |= set(ORDER_FIELDS.get(structure, ()))
    hidden = [f for f in (*_ALL_ORDERS, "bb_max_order", "bb_criterion") if f not in shown]
    if texts.get("bb_loop") == "open":
        hidden.append("bb_kp")
    if structure != "process":
        hidden.append("bb_offset")
    if texts.get("bb_validation") != "split":
        hidden.append("bb_fraction")
    else:
        hidden.append("bb_experiments")         # merged experiments are validated on another, not split
    if texts.get("bb_horizon") != "k":
        hidden.append("bb_k")
    return hidden


@dataclass(frozen=True)
class BlackBoxRequest:
    """A parsed black-box request: the experiment, the structure and its orders, how it is judged."""

    experiment: BlackBoxExperiment = field(default_factory=BlackBoxExperiment)
    structure: str = "arx"
    orders: tuple = (("na", 2), ("nb", 2), ("nk", 1))
    select: bool = False
    max_order: int = 3
    criterion: str = "validation fit"
    initial: str = "zero"
    horizon: int | None = None          # None: simulation
    detrend: bool = True                # each experiment's means removed first (MATLAB detrend)
    input_offset: str = "zero"          # process models: "estimate" fits y = G (u + c)

    def candidates(self):
        """The selection's candidates: the core's defaults (ARX's 32, n = 1..6, the four process kinds), or
        for ARMAX, OE and BJ every polynomial of order 1..``max_order`` with the delay given; the process
        kinds each with the input offset asked for."""
        if self.structure == "process" and self.input_offset == "estimate":
            from eha_core.identify.selection import PROCESS_KINDS

            return [{"kind": k, "input_offset": "estimate"} for k in PROCESS_KINDS]
        if self.structure not in ("armax", "oe", "bj"):
            return None
        nk = dict(self.orders).get("nk", 1)
        names = {"armax": ("na", "nb", "nc"), "oe": ("nb", "nf"), "bj": ("nb", "nc", "nd", "nf")}[self.structure]
        return [{**{n: k for n in names}, "nk": nk} for k in range(1, self.max_order + 1)]


def _detrends(choice: str, loop: str) -> bool:
    """Are the means removed: as chosen, or (auto) in closed loop only."""
    return choice == "remove" or (choice == "auto" and loop == "closed")


def parse_blackbox(texts: dict) -> tuple[BlackBoxRequest | None, dict]:
    """The request the form describes (None when a field is not valid), and a message per invalid field.

    Examples
    --------
    >>> req, errors = parse_blackbox(BB_DEFAULTS)
    >>> req.structure, req.orders, req.horizon, errors
    ('arx', (('na', 2), ('nb', 2), ('nk', 1)), None, {})
    >>> parse_blackbox({**BB_DEFAULTS, "bb_nb": "0"})[1]
    {'bb_nb': 'nb = 0 is not allowed: must lie in [1, 10]'}
    """
    from eha_core.errors import FieldError

    hidden = set(bb_hidden(texts))
    values, errors = parse_fields(_FIELDS.values(), texts, skip=hidden)
    if errors:
        return None, errors
    structure = values["bb_structure"]
    select = values["bb_choose"] == "select"
    try:
        experiment = BlackBoxExperiment(
            loop=values["bb_loop"], signal_type=values["bb_signal"], n_samples=values["bb_samples"],
            ts=float(values["bb_ts"]), kp=float(values.get("bb_kp", 10.0)), noise_x=float(values["bb_noise"]) * 1e-3,
            seed=values["bb_seed"], validation=values["bb_validation"],
            estimation_fraction=float(values.get("bb_fraction", 0.5)),
            n_experiments=int(values.get("bb_experiments", 1)))
    except FieldError as exc:          # the core's own rules (the form's bounds are within them)
        return None, {"bb_samples": str(exc)}
    names = [f[3:] for f in ORDER_FIELDS[structure] if f in values]
    orders = tuple((n, values[f"bb_{n}"]) for n in names)
    if structure == "process":
        orders = (("kind", values.get("bb_kind", "P1D")),) if not select else ()
    elif select:
        orders = (("nk", values["bb_nk"]),) if "bb_nk" in values else ()
    n_est = (experiment.n_samples if experiment.validation != "split"
             else int(round(experiment.estimation_fraction * experiment.n_samples)))
    if not select and structure != "process":
        # more parameters than samples: no estimate; said beside the largest order
        d = sum(v for n, v in orders if n not in ("nk", "n"))
        d += 2 * dict(orders).get("n", 0) if structure == "ss" else 0
        if d >= n_est // 2:
            name = max((f"bb_{n}" for n, _ in orders if n != "nk"), key=lambda f: values[f])
            errors[name] = str(FieldError(_FIELDS[name].display, texts.get(name, ""),
                                          f"the orders make {d} parameters; the estimation data have {n_est} samples: "
                                          f"keep the parameters under {n_est // 2}", value_text=texts.get(name, "")))
            return None, errors
    horizon = values["bb_k"] if values["bb_horizon"] == "k" else None
    return BlackBoxRequest(experiment, structure, orders, select, int(values.get("bb_max_order", 3)),
                           values.get("bb_criterion", "validation fit"), values["bb_initial"], horizon,
                           _detrends(values.get("bb_detrend", "auto"), experiment.loop),
                           values.get("bb_offset", "zero")), {}


# ---------------------------------------------------------------------------
# the computation (a worker): the core's calls, nothing else
# ---------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class BlackBoxOutcome:
    """What a run computed, as the core returned it: the data, the model, its fits (each a
    :class:`~eha_core.identify.blackbox.Comparison`), the residual tests on the validation data, the
    selection table (None with fixed orders) and the model for the board (or why there is none)."""

    request: BlackBoxRequest
    estimation: object
    validation: object
    model: object
    estimation_fit: object
    validation_fit: object
    residuals: object
    table: object = None
    board: BoardModel | None = None
    board_why: str = ""
    elapsed_s: float = 0.0


def _estimate(req: BlackBoxRequest, est):
    from eha_core.identify import polynomial, process, subspace

    o = dict(req.orders)
    if req.structure == "arx":
        return polynomial.arx(est, o["na"], o["nb"], o["nk"])
    if req.structure == "armax":
        return polynomial.armax(est, o["na"], o["nb"], o["nc"], o["nk"], initial=req.initial)
    if req.structure == "oe":
        return polynomial.oe(est, o["nb"], o["nf"], o["nk"], initial=req.initial)
    if req.structure == "bj":
        return polynomial.bj(est, o["nb"], o["nc"], o["nd"], o["nf"], o["nk"], initial=req.initial)
    if req.structure == "ss":
        return subspace.n4sid(est, o["n"], initial=req.initial)
    return process.procest(est, o["kind"], initial=req.initial, input_offset=req.input_offset)


def _quietly(fn, *args, **kwargs):
    """The core's answer, or None where the model cannot be simulated on the data (a failed estimate's
    NaN coefficients): the page says so instead of a fit."""
    try:
        with np.errstate(all="ignore"):
            return fn(*args, **kwargs)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError):
        return None


def board_model(model, kp: float, params, description: str) -> BoardModel:
    """A closed-loop black-box model (r [mm] -> x [mm]) as the board's continuous-time H(s) of r -> x:
    the core's :func:`~eha_core.identify.blackbox.continuous_equivalent` (its exact zero-order-hold
    equivalent, or the Tustin one where there is none, the description saying so). :class:`ValueError`
    for a model with no continuous-time equivalent."""
    from eha_core.identify.blackbox import continuous_equivalent

    c = continuous_equivalent(model)
    prefix = BOARD_PREFIX.get(model.structure, "BB")
    if c.how:
        description = f"{description}; on the board by {c.how}"
    return BoardModel(name=prefix, kind="blackbox", description=description, num=c.num, den=c.den,
                      input_delay=c.input_delay, ts=float(model.ts), kp=float(kp), params=params)


def compute_blackbox(req: BlackBoxRequest, params, cancel=None) -> BlackBoxOutcome:
    """Record the experiment on ``params``, estimate (or select) the model, compare it on both data sets
    with the request's horizon and initial conditions, test its residuals on the validation data, and
    make the board's model of a closed-loop estimate. Only the core computes."""
    from eha_core.cancel import check
    from eha_core.identify.blackbox import compare
    from eha_core.identify.selection import residual_tests, select_structure

    start = time.perf_counter()
    est, val = req.experiment.records(params)
    if req.detrend:
        est, val = est.detrended(), val.detrended()
    check(cancel)               # a newer request replaced this one while it recorded: stop before estimating
    table = None
    if req.select:
        table = select_structure(est, val, req.candidates(), structure=req.structure, criterion=req.criterion,
                                 horizon=req.horizon, initial=req.initial)
        model = table.best_model
        if model is None:           # no candidate succeeded: the first one's failure is shown
            model = _estimate(BlackBoxRequest(req.experiment, req.structure, _first_orders(table), False,
                                              initial=req.initial, horizon=req.horizon), est)
    else:
        model = _estimate(req, est)
    val_fit = _quietly(compare, model, val, req.horizon, req.initial)
    est_fit = _quietly(compare, model, est, req.horizon, req.initial)
    resid = _quietly(residual_tests, model, val)
    board, why = None, ""
    if req.experiment.loop != "closed":
        why = ("an open-loop model (u → x) describes the valve and the cylinder, not the closed loop r → x the board "
               "compares: estimate on the closed loop to put a model on the board")
    elif not model.success:
        why = "a failed estimate does not go on the board"
    else:
        e = req.experiment
        fit_words = val_fit.label if val_fit is not None else "no validation fit"
        description = (f"black-box {model.name}, closed loop r → x, Kp = {e.kp:g} V/m, Ts = {e.ts:g} s, "
                       f"{fit_words}")
        try:
            board = board_model(model, e.kp, params, description)
        except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
            why = " ".join(str(exc).split())
    return BlackBoxOutcome(req, est, val, model, est_fit, val_fit, resid, table, board, why,
                           time.perf_counter() - start)


def _first_orders(table) -> tuple:
    row = table.rows[0]
    return tuple(row.orders.items())


# ---------------------------------------------------------------------------
# the page
# ---------------------------------------------------------------------------
class BlackBoxPanel(Section):
    """Black-box identification of the actuator (see the module docstring)."""

    key = "blackbox"
    title = "Black-box models"
    defaults = BB_DEFAULTS
    # not a stop of the guide's three steps (it walks the paper's routes); the sub-tab is one click away
    guide_step: GuideStep | None = None
    form_css = "eha-bb-form"
    content_css = "eha-bb-form"
    run_buttons = ("Run black-box estimation",)

    def __init__(self, session, **kwargs):
        super().__init__(session, **kwargs)
        state = self.state
        self.result = None
        self.outcome: BlackBoxOutcome | None = None
        self._job = None
        self._busy = False                  # a run is waiting or computing: one at a time
        self._posted = False
        self.form = Form(spec=[g.to_spec() for g in BB_FORM], values=self.initial_texts(), url_defaults=BB_DEFAULTS,
                         width=270, css_classes=[self.form_css], margin=(5, 10))
        watch(self.form, self._update_enabled, "values")
        self.notice = pn.pane.HTML("", visible=False, width=270, css_classes=["eha-bb-notice"])
        self.button = pn.widgets.Button(label=self.run_buttons[0], color="primary", width=260,
                                        css_classes=["eha-run-bb"])
        on_click(self.button, lambda _e: self.run())
        self.progress = pn.indicators.Progress(value=-1, active=False, width=260, visible=False,
                                               css_classes=["eha-bb-progress-bar"])
        self.status = pn.pane.HTML("", width=270, css_classes=["eha-bb-status"])
        self.queue_note = pn.pane.HTML("", visible=False, width=270, css_classes=["eha-queue-note"],
                                       styles={"color": "#555", "font-size": "12px"})
        self.board_button = pn.widgets.Button(label="Put on the model board", width=260, disabled=True,
                                              css_classes=["eha-bb-to-board"])
        on_click(self.board_button, lambda _e: self.to_board())
        self.board_note = pn.pane.HTML("", width=270, css_classes=["eha-bb-board-note"])
        self.alert = pn.pane.Alert("", alert_type="danger", visible=False, sizing_mode="stretch_width",
                                   css_classes=["eha-bb-alert"])
        style = [bbr.CSS]
        self.model_pane = pn.pane.HTML("<p>Choose the experiment and the structure, and press “Run black-box "
                                       "estimation”.</p>", sizing_mode="stretch_width", css_classes=["eha-bb-model"],
                                       stylesheets=style)
        self.fits_pane = pn.pane.HTML("", sizing_mode="stretch_width", css_classes=["eha-bb-fits-pane"],
                                      stylesheets=style)
        self.selection_pane = pn.pane.HTML("", sizing_mode="stretch_width", css_classes=["eha-bb-selection-pane"],
                                           stylesheets=style, visible=False)
        self.residual_pane = pn.pane.HTML("", sizing_mode="stretch_width", css_classes=["eha-bb-residuals"],
                                          stylesheets=style)
        self.figures: dict = {}
        # a slot per figure, each filled with its figure once (then only its data change)
        self.slots = {key: pn.Column(sizing_mode="fixed" if key == "pz" else "stretch_width",
                                     css_classes=["eha-bb-plot", f"eha-bb-plot-{key}"], margin=0)
                      for key in ("fit", "sel", "resid", "pz")}
        self.model_pane.min_width = 300
        self.area = pn.Column(side_by_side(self.model_pane, self.slots["pz"]), self.fits_pane, self.slots["fit"],
                              self.selection_pane, self.slots["sel"], self.residual_pane, self.slots["resid"],
                              sizing_mode="stretch_width")
        self.view = ResultView("bb", self.area, run_hint="Press “Run black-box estimation” to update it.")
        state.param.watch(self._update_enabled, ["params", "valid"])
        self._update_enabled()

    # -- the request --------------------------------------------------------------------------------
    def request(self) -> tuple[BlackBoxRequest | None, dict]:
        return parse_blackbox(self.form.values)

    def run_key(self, req: BlackBoxRequest | None = None):
        """What a run now would be computed from (None while the form or tab 1 is not valid)."""
        req = self.request()[0] if req is None else req
        if req is None or not self.state.valid:
            return None
        return self.state.params, req

    def _update_enabled(self, *_events) -> None:
        req, errors = self.request()
        self.form.errors = errors
        self.form.hidden = bb_hidden(self.form.values)
        ok = self.state.valid
        self.button.disabled = self._busy or not ok or bool(errors)
        self.notice.object = run_off_notice(self.run_buttons[0], tab1_valid=ok, errors=errors, waiting=False)
        self.notice.visible = not ok or bool(errors)
        self.view.inputs_changed(self.run_key(req) if req is not None else None,
                                 why="" if ok else "a parameter on tab 1 is not valid")

    def _fail(self, message: str) -> None:
        self.alert.object = f"The black-box estimation failed: {html.escape(message)}"
        self.alert.visible = True

    # -- the run --------------------------------------------------------------------------------------
    def run(self):
        req, errors = self.request()
        if errors or req is None or not self.state.valid or self._busy:
            return None
        self.alert.visible = False
        try:       # what it may cost on a shared server, before it is queued
            self.check_cost()
        except ValueError as exc:
            self._fail(str(exc))
            return None
        params, key = self.state.params, self.run_key(req)

        def compute(token):
            return compute_blackbox(req, params, token)

        def show(out: BlackBoxOutcome, job):
            self.outcome = out
            self.result = out.model
            self._posted = False
            self.show_outcome(out, job)
            self.view.shown(key)
            self._update_enabled()

        self._running(True)
        job = self._job = self.runner.run("black-box estimation", compute, show, fail=self._fail, busy=[self.area],
                                          note=self._note)
        self.runner.then(job, self._ended)
        return job

    def _ended(self, job) -> None:
        """Whatever the run's end (shown, failed, cancelled): the button is on again."""
        if job is self._job:
            self._running(False)
            if job.state in (JobState.FAILED, JobState.CANCELLED):
                # the alert says why it failed; the line under the button no longer says it is running
                what = "failed" if job.state == JobState.FAILED else "was cancelled"
                shown = "; the results show the previous run" if self.outcome is not None else ""
                self.status.object = f"<span class='eha-warn'>The estimation {what}{shown}.</span>"

    def _running(self, on: bool) -> None:
        self._busy = on
        self.progress.active = on
        self.progress.visible = on
        if on:
            self.status.object = "<span class='eha-note'>Recording the experiment and estimating…</span>"
        self._update_enabled()

    def show_outcome(self, out: BlackBoxOutcome, job=None) -> None:
        """Draw ``out`` (on the page, under its lock)."""
        m, e = out.model, out.request.experiment
        self.model_pane.object = bbr.model_html(m, e.input_name, e.output_name)
        self.fits_pane.object = ("<h4>Fits</h4>" + bbr.fits_html(out.estimation_fit, out.validation_fit, m.fit,
                                                                 failed=not m.success)
                                 + f"<p class='eha-note'>Experiment: "
                                   f"{html.escape(_experiment_text(e, out.request.detrend))}.</p>")
        if out.table is not None:
            self.selection_pane.object = ("<h4>Selection of the orders</h4>" + bbr.selection_html(out.table))
            self.selection_pane.visible = True
        else:
            self.selection_pane.visible = False
        self._draw(out)
        self.residual_pane.object = ("<h4>Residual tests on the validation data</h4>"
                                     + bbr.verdicts_html(out.residuals)
                                     + f"<p class='eha-note'>{self.figures['resid'].band_text()}</p>")
        took = job.run_s if job is not None else out.elapsed_s
        self.status.object = (f"<span class='{'eha-ok' if m.success else 'eha-warn'}'>"
                              f"{html.escape(m.name)} {'estimated' if m.success else 'failed'} in {took:.1f} s.</span>")
        self.board_button.disabled = out.board is None
        self.board_note.object = (f"<span class='eha-note'>{html.escape(out.board_why)}.</span>" if out.board is None
                                  else "<span class='eha-note'>The board compares it, as H(s) of r → x, with the "
                                       "other routes' models on its validation record.</span>")

    def _figure(self, key: str, make):
        fig = self.figures.get(key)
        if fig is None:
            fig = self.figures[key] = make()
        return fig

    def _draw(self, out: BlackBoxOutcome) -> None:
        """The figures: made once, their data replaced by each run."""
        shown = []
        if out.validation_fit is not None:
            fit = self._figure("fit", bbr.BlackBoxFitFigure)
            fit.update(out.validation_fit, out.request.experiment.output_name)
            shown.append(("fit", fit))
        corr = self._figure("resid", bbr.CorrelationFigure)
        corr.update(out.residuals)
        shown.append(("resid", corr))
        pz = self._figure("pz", bbr.ZPlaneFigure)
        pz.update(_quietly(out.model.poles), _quietly(out.model.zeros))
        shown.append(("pz", pz))
        if out.table is not None:
            sel = self._figure("sel", bbr.SelectionFigure)
            sel.update(out.table)
            shown.append(("sel", sel))
        panes = self.figures.setdefault("_panes", {})
        for key, slot in self.slots.items():
            fig = dict(shown).get(key)
            if fig is not None and key not in panes and key == "resid":
                # the two correlations side by side where they fit, one above the other on a narrow page
                panes[key] = pn.FlexBox(*(pn.pane.Bokeh(f, width=fig.width + 10, height=f.height + 10)
                                          for f in fig.figs), sizing_mode="stretch_width")
            elif fig is not None and key not in panes:
                # the z-plane's square plot area is its figure's own (frame_width, frame_height): the pane
                # keeps Panel from giving it a width of its own
                sizing = ({"sizing_mode": "fixed", "width": fig.size, "height": fig.size + 40} if key == "pz"
                          else {"sizing_mode": "stretch_width"})
                panes[key] = pn.pane.Bokeh(fig.layout, **sizing)
            objects = [panes[key]] if fig is not None else []
            if list(slot.objects) != objects:
                slot.objects = objects
            slot.visible = bool(objects)

    # -- the board ------------------------------------------------------------------------------------
    def to_board(self) -> None:
        """Put the last closed-loop model on the model board (once per run)."""
        out = self.outcome
        if out is None or out.board is None or self._posted:
            return
        self.session.post("board", out.board)
        self._posted = True
        self.board_button.disabled = True
        prefix = html.escape(out.board.name)
        self.board_note.object = (f"<span class='eha-ok'>{html.escape(out.model.name)} is on the model board (the "
                                  f"board numbers its {prefix} models: {prefix}1, {prefix}2, …): open the Model board "
                                  "sub-tab to compare it.</span>")

    # -- the section's protocol -----------------------------------------------------------------------
    def result_views(self) -> list:
        return [self.view]

    def run_cost(self) -> RunCost | None:
        """The nonlinear simulation of the record(s): N × Ts seconds each, at the simulator's steps."""
        req, _errors = self.request()
        if req is None:
            return None
        e = req.experiment
        experiments = 1 if e.validation == "split" else 2
        simulated_s = e.n_samples * e.ts * experiments
        # the simulation's states and the regressions' matrices, a few dozen numbers a sample
        peak = e.n_samples * experiments * 8 * 64
        return RunCost("N × Ts", f"{e.n_samples} × {e.ts:g} s", int(simulated_s / DEFAULT_H_MAX), peak, simulated_s,
                       "use fewer samples or a shorter sample time")

    def kept_work(self) -> KeptWork | None:
        return KeptWork({"views": ["bb"]}) if self.view.is_current else None

    @classmethod
    def restore_work(cls, kept: KeptWork, texts) -> list[RestoreStep]:
        if "bb" in (kept.run or {}).get("views", ()):
            return [RestoreStep(cls.title, lambda section: section.run())]
        return []

    def snapshot(self) -> SectionSnapshot:
        return SectionSnapshot(self.key, self.title, self.settings(), stale=self.is_stale(), content=self.outcome)

    @classmethod
    def report(cls, snapshot: SectionSnapshot, hidden=()) -> ReportPart | None:
        out = snapshot.content
        if out is None:
            return None
        m, e = out.model, out.request.experiment
        figures = {}
        body = stale_note(snapshot) + bbr.model_html(m, e.input_name, e.output_name)
        body += "<h3>Fits</h3>" + bbr.fits_html(out.estimation_fit, out.validation_fit, m.fit, failed=not m.success)
        if out.validation_fit is not None:
            fit = bbr.BlackBoxFitFigure()
            fit.update(out.validation_fit, e.output_name)
            figures["bb_fit"] = fit.layout
            body += "{{bb_fit}}"
        if out.table is not None:
            sel = bbr.SelectionFigure()
            sel.update(out.table)
            figures["bb_sel"] = sel.layout
            body += "<h3>Selection of the orders</h3>" + bbr.selection_html(out.table) + "{{bb_sel}}"
        corr = bbr.CorrelationFigure()
        corr.update(out.residuals)
        figures["bb_resid"] = corr.layout
        pz = bbr.ZPlaneFigure()
        pz.update(_quietly(m.poles), _quietly(m.zeros))
        figures["bb_pz"] = pz.layout
        body += ("<h3>Residual tests on the validation data</h3>" + bbr.verdicts_html(out.residuals)
                 + "{{bb_resid}}{{bb_pz}}")
        body += f"<p class='eha-note'>Experiment: {html.escape(_experiment_text(e, out.request.detrend))}.</p>"
        return ReportPart("Black-box models", body, figures)

    def _note(self, text: str) -> None:
        self.queue_note.object = text
        self.queue_note.visible = bool(text)

    def __panel__(self):
        controls = pn.Column(self.form, self.notice, self.button, self.progress, self.status, self.board_button,
                             self.board_note, self.queue_note, width=290)
        explain = pn.pane.HTML(
            "<p class='eha-note'>Black-box identification (as MATLAB's System Identification Toolbox): a linear "
            "model y = G(q) u + H(q) e of the chosen structure is fitted to a record of tab 1's actuator (the "
            "nonlinear model of eqs. 1-4, so a linear structure only approximates it) and judged on other data: "
            "its fit, its residuals' whiteness and their independence of the input.</p>",
            sizing_mode="stretch_width")
        results = pn.Column(explain, self.alert, self.view.banner, self.area, sizing_mode="stretch_width",
                            min_width=440)
        return side_by_side(controls, results)


def _experiment_text(e: BlackBoxExperiment, detrend: bool = True) -> str:
    loop = (f"closed loop r → x, Kp = {e.kp:g} V/m" if e.loop == "closed" else "open loop u → x")
    val = (f"a second experiment (seed {e.seed + e.n_experiments})" if e.validation == "second experiment"
           else f"the record's last {1 - e.estimation_fraction:.0%}")
    merged = "" if e.n_experiments == 1 else f" x {e.n_experiments} experiments merged (seeds {e.seed}-" \
                                              f"{e.seed + e.n_experiments - 1})"
    means = "means removed" if detrend else "means kept"
    return (f"{loop}, {e.signal_type.upper()} excitation, N = {e.n_samples}{merged}, Ts = {e.ts:g} s, position "
            f"noise σ = {e.noise_x * 1e3:g} mm, seed {e.seed}, {means}; validation on {val}")
