"""Choosing a black-box model's structure and orders, and testing its residuals (MATLAB ``arxstruc``,
``selstruc``, ``resid``).

:func:`select_structure` estimates every candidate on the estimation data and judges it twice: by
the estimation data's loss and information criteria (AIC, BIC, as
:func:`eha_core.identify.blackbox.criteria` defines them, MATLAB's raw values) and by its fit on
*other* data, the validation data (:func:`eha_core.identify.blackbox.compare`, by simulation unless a
prediction horizon is given). The result, a :class:`SelectionTable`, has one row per candidate and
the row picked by the chosen criterion.

For ARX the whole grid is computed from one QR factorisation (:func:`arx_grid`, as ``arxstruc``
does): the triangular factor ``R`` of the regression matrix of the largest structure holds every
smaller structure's normal equations (``Phi_S^T Phi_S = R_S^T R_S`` for any set ``S`` of its
columns), so each candidate is one small QR of ``R``'s columns, plus the few first rows that the
candidate's shorter lags add (:func:`eha_core.identify.polynomial.arx` begins its rows after each
structure's own longest lag). Its losses equal :func:`~eha_core.identify.polynomial.arx`'s.

Which criterion picks by default: the validation fit (:data:`DEFAULT_CRITERION`), as the data can
tell it. An extra parameter moves a validation fit by noise alone, so the highest fit by a hair is as
often a larger model as the true one (on 100 records of a known ARX(2, 2, 1) system at 20 dB output
SNR, N = 1000 for estimation and for validation, the 32 default structures, the highest fit was the
true structure in 35). The pick is therefore the fewest parameters whose validation loss is not
significantly above the best's: the mean of the difference of their squared errors within two of its
standard errors (batch means over 20 blocks: a simulation's errors are correlated from sample to
sample). On the same 100 records it finds the true orders in 96, BIC in 99 and AIC in 88;
``criterion="bic"`` and ``"aic"`` pick by the estimation data's criteria.

:func:`residual_tests` judges a model's one-step prediction errors (MATLAB ``resid``): white, and
uncorrelated with the input, or not.

Examples
--------
>>> import numpy as np, scipy.signal
>>> from eha_core.identify.blackbox import IdData
>>> rng = np.random.default_rng(0)
>>> def record(n):
...     u, e = rng.standard_normal(n), 0.05 * rng.standard_normal(n)
...     return IdData(scipy.signal.lfilter([0, 1.0, 0.5], [1, -1.5, 0.7], u)
...                   + scipy.signal.lfilter([1.0], [1, -1.5, 0.7], e), u, 0.1)
>>> table = select_structure(record(1000), record(1000))
>>> len(table.rows), table.best.name, table.criterion
(32, 'ARX(na=2, nb=2, nk=1)', 'validation fit')
>>> residual_tests(table.best_model, record(1000)).passed
True
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

from .._checks import not_allowed, whole_number
from .blackbox import IdData, LinearModel, compare, horizon_words, initial_words, predict

__all__ = ["SelectionRow", "SelectionTable", "ResidualTests", "select_structure", "arx_grid", "residual_tests",
           "STRUCTURES", "CRITERIA", "DEFAULT_CRITERION", "ARX_GRID", "SS_MAX_ORDER", "PROCESS_KINDS"]

#: What each structure's candidate (a dict) names: its orders.
STRUCTURES = {
    "arx": ("na", "nb", "nk"),
    "armax": ("na", "nb", "nc", "nk"),
    "oe": ("nb", "nf", "nk"),
    "bj": ("nb", "nc", "nd", "nf", "nk"),
    "ss": ("n",),
    "process": ("kind",),
}
#: What a candidate may give besides its orders (passed on to the estimator).
_EXTRAS = {"armax": ("initial",), "oe": ("initial",), "bj": ("initial",), "ss": ("initial",),
           "process": ("initial", "delay", "input_offset")}
#: How the picked row is chosen.
CRITERIA = ("bic", "aic", "validation fit")
#: The validation fit, as the validation data can tell it: see the module docstring.
DEFAULT_CRITERION = "validation fit"
#: The default ARX grid, MATLAB's ``struc(1:4, 1:4, 1:2)`` (32 structures).
ARX_GRID = {"na": range(1, 5), "nb": range(1, 5), "nk": range(1, 3)}
#: The default state-space orders, 1 to this.
SS_MAX_ORDER = 6
#: The process models tried by default (:func:`eha_core.identify.process.procest` takes more kinds).
PROCESS_KINDS = ("P1D", "P2D", "P1DI", "P2DI")


# ---------------------------------------------------------------------------
# results
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class SelectionRow:
    """One candidate: its orders, its criteria on the estimation data and its fit on validation data.

    Attributes
    ----------
    structure : str
        ``"arx"``, ``"armax"``, ``"oe"``, ``"bj"``, ``"ss"`` or ``"process"``.
    orders : dict
        The candidate's orders (``{"na": 2, "nb": 2, "nk": 1}``).
    name : str
        ``"ARX(na=2, nb=2, nk=1)"``.
    n_params : int
    loss, aic, bic, fpe : float
        Of the one-step prediction errors on the estimation data
        (:class:`~eha_core.identify.blackbox.Criteria`).
    validation_fit : float
        NRMSE fit [%] on the validation data.
    horizon : int or None
        The validation fit's horizon (None: simulation).
    initial : str
        The validation fit's initial conditions, ``"zero"`` or ``"estimate"``.
    success : bool
        The estimate's own verdict.
    message : str
    """

    structure: str
    orders: dict
    name: str
    n_params: int
    loss: float
    aic: float
    bic: float
    fpe: float
    validation_fit: float
    horizon: int | None
    initial: str
    success: bool
    message: str = ""

    @property
    def validation_label(self) -> str:
        """The validation fit in the words of :attr:`Comparison.label`."""
        return f"fit {self.validation_fit:.1f} % ({horizon_words(self.horizon)}, {initial_words(self.initial)})"


@dataclass(frozen=True, eq=False)
class SelectionTable:
    """Every candidate of a structure selection and the one picked (MATLAB ``arxstruc`` + ``selstruc``).

    Attributes
    ----------
    structure : str
    rows : tuple of SelectionRow
    criterion : str
        ``"bic"``, ``"aic"`` or ``"validation fit"``: how :attr:`best` was picked.
    best_index : int or None
        The picked row (None when no candidate succeeded).
    best_model : EstimateFields or None
        The picked candidate's estimate.
    horizon : int or None
        The validation fits' horizon (None: simulation).
    initial : str
        The validation fits' initial conditions.
    estimation_name, validation_name : str
        What the data were.
    n_samples : int
        Samples of the estimation data.
    singular_values : numpy.ndarray or None
        For ``"ss"``: the subspace SVD's singular values (a gap after the ``n``-th says ``n`` states).
    """

    structure: str
    rows: tuple
    criterion: str
    best_index: int | None
    best_model: object
    horizon: int | None
    initial: str
    estimation_name: str = ""
    validation_name: str = ""
    n_samples: int = 0
    singular_values: np.ndarray | None = field(default=None, repr=False)

    @property
    def best(self) -> SelectionRow | None:
        """The row picked by :attr:`criterion`."""
        return None if self.best_index is None else self.rows[self.best_index]

    def to_pandas(self):
        """The table as a :class:`pandas.DataFrame`, one row per candidate, ``picked`` marking the best."""
        import pandas as pd

        return pd.DataFrame([{
            "name": r.name, **{k: v for k, v in r.orders.items()}, "n_params": r.n_params, "loss": r.loss,
            "aic": r.aic, "bic": r.bic, "fpe": r.fpe, "validation fit [%]": r.validation_fit,
            "horizon": horizon_words(r.horizon), "initial": initial_words(r.initial), "success": r.success,
            "picked": i == self.best_index} for i, r in enumerate(self.rows)])

    def to_dict(self) -> dict:
        """The table as JSON types (the picked model as its own ``to_dict``)."""
        return {
            "structure": self.structure, "criterion": self.criterion, "best_index": self.best_index,
            "horizon": horizon_words(self.horizon), "initial": initial_words(self.initial),
            "estimation": self.estimation_name, "validation": self.validation_name, "n_samples": self.n_samples,
            "rows": [{"name": r.name, "orders": dict(r.orders), "n_params": r.n_params, "loss": r.loss,
                      "aic": r.aic, "bic": r.bic, "fpe": r.fpe, "validation_fit": r.validation_fit,
                      "validation_label": r.validation_label, "success": r.success, "message": r.message}
                     for r in self.rows],
            "singular_values": None if self.singular_values is None else
            [float(v) for v in self.singular_values],
            "best_model": None if self.best_model is None else self.best_model.to_dict(),
        }

    def __repr__(self) -> str:
        best = "none succeeded" if self.best is None else f"{self.best.name} by {self.criterion}"
        return f"<SelectionTable of {len(self.rows)} {self.structure.upper()} candidates: {best}>"


@dataclass(frozen=True, eq=False)
class ResidualTests:
    """A model's one-step prediction errors on data, and the verdicts of their tests (MATLAB ``resid``).

    Attributes
    ----------
    residuals : numpy.ndarray
        ``y - y_hat(t | t-1)``.
    analysis : ResidualAnalysis
        Their autocorrelation and cross-correlation with the input
        (:func:`eha_core.identify.validate.residual_analysis`).
    assessment : ResidualAssessment
        The verdicts (:func:`eha_core.identify.assessment.assess_residuals`).
    model_name, data_name : str
    """

    residuals: np.ndarray
    analysis: object
    assessment: object
    model_name: str = ""
    data_name: str = ""

    @property
    def passed(self) -> bool:
        """White and uncorrelated with the input."""
        return bool(self.assessment.passed)

    @property
    def whiteness(self):
        return self.assessment.whiteness

    @property
    def independence(self):
        return self.assessment.independence

    def __repr__(self) -> str:
        def word(v):
            return "passed" if v.passed else "failed"

        return (f"<ResidualTests of {self.model_name} on {self.data_name}: whiteness {word(self.whiteness)}, "
                f"independence {word(self.independence)}>")


# ---------------------------------------------------------------------------
# checks
# ---------------------------------------------------------------------------
def _check_data(est, val) -> None:
    if not isinstance(est, IdData):
        raise not_allowed("estimation data", type(est).__name__, "an IdData (eha_core.identify.blackbox.IdData)")
    if not isinstance(val, IdData):
        raise not_allowed("validation data", type(val).__name__, "an IdData (eha_core.identify.blackbox.IdData)")
    if not math.isclose(val.ts, est.ts, rel_tol=1e-9):
        raise not_allowed("validation sample time", f"{val.ts:g} s",
                          f"the validation data need the estimation data's sample time, {est.ts:g} s")


def _size(structure: str, orders: dict) -> tuple[int, int]:
    """Parameters and longest lag of a candidate (as the estimators count them)."""
    if structure == "ss":
        # n4sid: 3 n parameters (a, b, c of G and H); its horizon of n + 1 block rows needs 6 (n + 1) - 1 samples
        n = orders["n"]
        return 3 * n, 3 * n + 5
    if structure == "process":
        kind = orders["kind"]                   # K, one or two time constants, and Td with D
        return 1 + int(kind[1]) + ("D" in kind), 0
    g = {k: orders.get(k, 0) for k in ("na", "nb", "nc", "nd", "nf", "nk")}
    return (g["na"] + g["nb"] + g["nc"] + g["nd"] + g["nf"],
            max(g["na"], g["nb"] + g["nk"] - 1, g["nc"], g["nd"], g["nf"]))


def _checked_candidate(structure: str, candidate, est: IdData) -> dict:
    """A candidate's orders, each a whole number the estimation record supports, as a dict."""
    names = STRUCTURES[structure]
    if structure == "ss" and not isinstance(candidate, dict):
        candidate = {"n": candidate}
    if structure == "process" and isinstance(candidate, str):
        candidate = {"kind": candidate}
    if not isinstance(candidate, dict):
        raise not_allowed("candidates", candidate, f"each candidate is a dict of the orders {', '.join(names)}")
    unknown = sorted(set(candidate) - set(names) - set(_EXTRAS.get(structure, ())))
    missing = [n for n in names if n not in candidate]
    if unknown or missing:
        raise not_allowed("candidates", candidate, f"{structure} takes the orders {', '.join(names)}"
                                                   + (f" (and {', '.join(_EXTRAS[structure])})"
                                                      if structure in _EXTRAS else ""))
    orders = dict(candidate)
    if structure == "process":
        from .process import KINDS

        kind = orders["kind"].strip().upper() if isinstance(orders["kind"], str) else None
        if kind not in KINDS:
            raise not_allowed("kind", orders["kind"], f"a process type code, one of {', '.join(KINDS)}")
        orders["kind"] = kind
    else:
        for n in names:
            orders[n] = whole_number(n, candidate[n], 1 if n in ("nb", "n") else 0)
    shortest = min(y.size for y, _u in est.segments())
    where = "the record" if est.n_experiments == 1 else "the shortest experiment"
    if orders.get("nk", 0) >= shortest:
        raise not_allowed("nk", candidate["nk"], f"the input delay must be shorter than the data: {where} has "
                                                 f"{shortest} samples")
    n_params, lag = _size(structure, orders)
    if shortest < n_params + lag:
        key = max((n for n in names if n != "kind"), key=lambda n: orders[n], default="kind")
        raise not_allowed(key, candidate[key], f"{n_params} parameters and a longest lag of {lag} samples need at "
                                               f"least {n_params + lag} samples in each experiment and {where} "
                                               f"has {shortest}: lower the orders or give a longer record")
    return orders


def _checked_criterion(criterion: str) -> str:
    key = str(criterion).strip().lower().replace("-", " ").replace("_", " ")
    if key not in CRITERIA:
        raise not_allowed("criterion", criterion, "aic, bic or validation fit")
    return key


#: Blocks of the validation errors whose means give the spread of a difference of two models' losses
#: (batch means: the errors of a simulation are correlated from sample to sample).
_BATCHES = 20
#: A smaller model is as good as the best one when its validation loss exceeds the best's by fewer
#: than this many standard errors of the difference.
_EQUAL_WITHIN_SE = 2.0


def _as_good(err_small, err_best) -> bool:
    """Is the validation loss of ``err_small`` within the data's own uncertainty of ``err_best``'s?"""
    d = err_small ** 2 - err_best ** 2
    if d.size < 2 * _BATCHES:
        return float(np.mean(d)) <= 0.0
    means = np.array([b.mean() for b in np.array_split(d, _BATCHES)])
    spread = float(np.std(means, ddof=1)) / math.sqrt(_BATCHES)
    return float(np.mean(d)) <= _EQUAL_WITHIN_SE * spread


def _pick(rows, criterion: str, errors=None) -> int | None:
    usable = [i for i, r in enumerate(rows) if r.success and np.isfinite(getattr(r, _KEY[criterion]))]
    if not usable:
        return None
    if criterion == "validation fit":
        top = max(usable, key=lambda i: (rows[i].validation_fit, -rows[i].n_params))
        if errors is None or errors[top] is None:
            return top
        # the best validation fit, up to what the validation data can tell apart: the fewest parameters
        # whose validation loss is not significantly above the best's (an extra parameter moves the fit
        # by noise alone, and the best fit by a hair is as often a larger model as the true one)
        for i in sorted(usable, key=lambda i: (rows[i].n_params, -rows[i].validation_fit)):
            if rows[i].n_params >= rows[top].n_params:
                break
            if errors[i] is not None and _as_good(errors[i], errors[top]):
                return i
        return top
    key = _KEY[criterion]
    # ties (equal criteria) go to the fewer parameters, then the earlier row
    return min(usable, key=lambda i: (getattr(rows[i], key), rows[i].n_params, i))


_KEY = {"aic": "aic", "bic": "bic", "validation fit": "validation_fit"}


def _name(structure: str, orders: dict) -> str:
    if structure == "ss":
        return f"State space (n4sid, n={orders['n']})"
    if structure == "process":
        return str(orders["kind"])
    return f"{structure.upper()}(" + ", ".join(f"{k}={orders[k]}" for k in STRUCTURES[structure]) + ")"


# ---------------------------------------------------------------------------
# ARX: the whole grid from one QR
# ---------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class _ArxPolynomials(LinearModel):
    """An ARX candidate's polynomials, enough to simulate it on validation data."""

    a: np.ndarray
    b: np.ndarray
    ts: float

    def g_poly(self):
        return self.b, self.a

    def h_poly(self):
        return np.array([1.0]), self.a

    def polynomial_form(self):
        # as polynomial.PolynomialModel: the predictor B u + (1 - A) y, never 1/A
        one = np.array([1.0])
        return self.a, self.b, one, one, one


def _lag_columns(y, u, rows, na_max: int, u_lags) -> np.ndarray:
    """``[-y(t-1) .. -y(t-na_max), u(t-l) for l in u_lags, y(t)]`` for the row indices ``rows``."""
    cols = [-y[rows - k] for k in range(1, na_max + 1)] + [u[rows - lag] for lag in u_lags] + [y[rows]]
    return np.column_stack(cols)


def _arx_rows(est: IdData, val: IdData, candidates, horizon, initial):
    """The rows of every ARX candidate: its loss from one QR of the largest regression, its fit on ``val``."""
    from .blackbox import criteria

    na_max = max(c["na"] for c in candidates)
    nk_min = min(c["nk"] for c in candidates)
    u_lags = list(range(nk_min, max(c["nk"] + c["nb"] for c in candidates)))
    lag_of = [max(c["na"], c["nb"] + c["nk"] - 1) for c in candidates]
    common = max(lag_of)
    segments = est.segments()
    # the rows every candidate uses (t >= the longest lag of all), factorised once
    full = np.vstack([_lag_columns(y, u, np.arange(common, y.size), na_max, u_lags) for y, u in segments])
    r_full = np.linalg.qr(full, mode="r")
    target = full.shape[1] - 1
    rows = []
    for c, lag in zip(candidates, lag_of, strict=True):
        cols = list(range(c["na"])) + [na_max + u_lags.index(k) for k in range(c["nk"], c["nk"] + c["nb"])]
        # the first rows this candidate has and the grid's longest lag has not (arx begins at its own lag)
        extra = [_lag_columns(y, u, np.arange(lag, common), na_max, u_lags) for y, u in segments if common > lag]
        stacked = np.vstack([r_full] + extra)[:, cols + [target]]
        d = len(cols)
        r = np.linalg.qr(stacked, mode="r")
        n_rows = full.shape[0] + sum(e.shape[0] for e in extra)
        diag = np.abs(np.diag(r[:d, :d]))
        name = _name("arx", c)
        if d and (diag.size < d or diag.min() <= 1e-10 * max(diag.max(), 1e-300)):
            rows.append((c, name, None, d, "the regressors are (nearly) collinear: lower na or nb, or excite "
                                           "the input more"))
            continue
        theta = scipy.linalg.solve_triangular(r[:d, :d], r[:d, d], check_finite=False)
        sse = float(r[d, d] ** 2) if r.shape[0] > d else 0.0
        # the criteria of n_rows residuals whose mean square is sse / n_rows (blackbox.criteria's formulas)
        crit = criteria(np.full(n_rows, math.sqrt(sse / n_rows)), d)
        model = _ArxPolynomials(np.concatenate([[1.0], theta[:c["na"]]]),
                                np.concatenate([np.zeros(c["nk"]), theta[c["na"]:]]), est.ts)
        rows.append((c, name, (crit, model), d, "least squares: unique solution"))
    out, errors = [], []
    for c, name, result, d, message in rows:
        if result is None:
            errors.append(None)
            out.append(SelectionRow("arx", dict(c), name, d, math.nan, math.nan, math.nan, math.nan, math.nan,
                                    horizon, initial, False, message))
            continue
        crit, model = result
        with np.errstate(all="ignore"):
            comparison = compare(model, val, horizon, initial)
        fit = comparison.fit_percent
        errors.append(comparison.y - comparison.yhat)
        out.append(SelectionRow("arx", dict(c), name, d, crit.loss, crit.aic, crit.bic, crit.fpe,
                                fit if math.isfinite(fit) else -math.inf, horizon, initial, True, message))
    return out, errors


def arx_grid(est: IdData, val: IdData, na=ARX_GRID["na"], nb=ARX_GRID["nb"], nk=ARX_GRID["nk"], *,
             criterion: str = DEFAULT_CRITERION, horizon=None, initial: str = "zero") -> SelectionTable:
    """Every ARX structure of the grid ``na x nb x nk``, from one QR factorisation (MATLAB ``arxstruc``).

    Parameters
    ----------
    est, val : IdData
        Estimation and validation data (the same sample time).
    na, nb, nk : iterable of int
        The orders tried (default MATLAB's ``struc(1:4, 1:4, 1:2)``).
    criterion : {"bic", "aic", "validation fit"}
        How the best row is picked.
    horizon : int or None
        The validation fit's horizon: None (simulation, the default) or k steps ahead.
    initial : {"zero", "estimate"}
        The validation fit's initial conditions.

    Returns
    -------
    SelectionTable

    Examples
    --------
    >>> import numpy as np, scipy.signal
    >>> rng = np.random.default_rng(2)
    >>> u = rng.standard_normal(3000)
    >>> y = scipy.signal.lfilter([0, 0, 1.0], [1, -0.7], u) + scipy.signal.lfilter([1], [1, -0.7],
    ...                                                                          0.1 * rng.standard_normal(3000))
    >>> est, val = IdData(y, u, 1.0).split(0.5)
    >>> arx_grid(est, val, na=[1, 2], nb=[1, 2], nk=[1, 2, 3]).best.orders
    {'na': 1, 'nb': 1, 'nk': 2}
    """
    candidates = [{"na": a, "nb": b, "nk": k} for a in na for b in nb for k in nk]
    return select_structure(est, val, candidates, structure="arx", criterion=criterion, horizon=horizon,
                            initial=initial)


# ---------------------------------------------------------------------------
# any structure
# ---------------------------------------------------------------------------
def _estimator(structure: str):
    if structure == "ss":
        from .subspace import n4sid

        return n4sid
    if structure == "process":
        from .process import procest

        return procest
    from . import polynomial

    return getattr(polynomial, structure)


def _row(structure, orders, model, val, horizon, initial):
    """The candidate's row, and its errors on the validation data (None when it cannot be simulated)."""
    crit = model.criteria
    fit, errors = math.nan, None
    if np.all(np.isfinite(np.asarray(model.params, float))):
        with np.errstate(all="ignore"):
            comparison = compare(model, val, horizon, initial)
        fit, errors = comparison.fit_percent, comparison.y - comparison.yhat
    return SelectionRow(structure, dict(orders), model.name, int(crit.n_params), crit.loss, crit.aic, crit.bic,
                        crit.fpe, fit if math.isfinite(fit) else -math.inf, horizon, initial,
                        bool(model.success), model.message), errors


def select_structure(est: IdData, val: IdData, candidates=None, *, structure: str = "arx",
                     criterion: str = DEFAULT_CRITERION, horizon=None, initial: str = "zero") -> SelectionTable:
    """Estimate every candidate structure and pick one (MATLAB ``arxstruc``/``selstruc``, ``n4sid`` order choice).

    Parameters
    ----------
    est : IdData
        Estimation data.
    val : IdData
        Validation data, the same sample time (another experiment, or the rest of the record).
    candidates : list of dict, optional
        The orders of each candidate, e.g. ``[{"na": 2, "nb": 2, "nk": 1}, ...]`` (ARX), ``[{"n": 3}]``
        or ``[3]`` (state space), ``[{"kind": "P2D"}]`` or ``["P2D"]`` (process; ``delay`` and ``initial``
        may be added and go to the estimator, as ``initial`` may for ARMAX, OE and BJ). Default: ARX
        :data:`ARX_GRID` (32 structures), state space ``n = 1 .. SS_MAX_ORDER``, process every kind;
        ARMAX, OE and BJ need them given.
    structure : {"arx", "armax", "oe", "bj", "ss", "process"}
        The model structure.
    criterion : {"bic", "aic", "validation fit"}
        How :attr:`SelectionTable.best` is picked (default :data:`DEFAULT_CRITERION`, see the module
        docstring): the least BIC or AIC on the estimation data, or the best fit on the validation data
        (the fewest parameters whose validation loss the data cannot tell from the best's).
        Only successful estimates are picked.
    horizon : int or None
        The validation fit's horizon: None (simulation, the default, MATLAB ``compare(..., Inf)``) or k.
    initial : {"zero", "estimate"}
        The validation fit's initial conditions (default zero).

    Returns
    -------
    SelectionTable
        ``singular_values`` set for ``"ss"``.

    Examples
    --------
    >>> import numpy as np
    >>> d = IdData(np.zeros(20), np.ones(20), 0.1)
    >>> select_structure(d, d, [])
    Traceback (most recent call last):
    ...
    eha_core._checks.FieldError: candidates = [] is not allowed: give at least one arx candidate (a dict of na, nb, nk)
    """
    key = str(structure).strip().lower()
    if key not in STRUCTURES:
        raise not_allowed("structure", structure, "one of " + ", ".join(STRUCTURES))
    _check_data(est, val)
    criterion = _checked_criterion(criterion)
    with np.errstate(all="ignore"):
        _ = compare(_ArxPolynomials(np.ones(1), np.ones(1), est.ts), val, horizon, initial)   # checks both
    horizon = None if horizon is None or (isinstance(horizon, float) and math.isinf(horizon)) else int(horizon)
    if candidates is None:
        if key == "arx":
            candidates = [{"na": a, "nb": b, "nk": k} for a in ARX_GRID["na"] for b in ARX_GRID["nb"]
                          for k in ARX_GRID["nk"]]
        elif key == "ss":
            shortest = min(y.size for y, _u in est.segments())
            # as many orders as the record holds (n4sid's horizon needs about 6 (2n) samples)
            top = max(1, min(SS_MAX_ORDER, (shortest // 12) - 1))
            candidates = [{"n": n} for n in range(1, top + 1)]
        elif key == "process":
            candidates = [{"kind": k} for k in PROCESS_KINDS]
        else:
            raise not_allowed("candidates", None, f"{key} needs its candidates given (a list of dicts of "
                                                  f"{', '.join(STRUCTURES[key])})")
    candidates = list(candidates)
    if not candidates:
        raise not_allowed("candidates", [], f"give at least one {key} candidate (a dict of "
                                            f"{', '.join(STRUCTURES[key])})")
    orders = [_checked_candidate(key, c, est) for c in candidates]
    singular_values = None
    if key == "arx":
        rows, errors = _arx_rows(est, val, orders, horizon, initial)
    else:
        estimate = _estimator(key)
        if key == "ss":
            from .subspace import ss_order_svd

            top = max(o["n"] for o in orders)
            try:
                singular_values = ss_order_svd(est, top)
            except ValueError as exc:
                if getattr(exc, "field", None) == "max_order":
                    raise not_allowed("n", top, exc.what) from None
                raise
        models, rows, errors = [], [], []
        for o in orders:
            model = estimate(est, **o)
            models.append(model)
            row, err = _row(key, o, model, val, horizon, initial)
            rows.append(row)
            errors.append(err)
    best = _pick(rows, criterion, errors)
    best_model = None
    if best is not None:
        if key == "arx":
            from .polynomial import arx

            best_model = arx(est, **{k: orders[best][k] for k in STRUCTURES["arx"]})
        else:
            best_model = models[best]
    return SelectionTable(key, tuple(rows), criterion, best, best_model, horizon, initial, est.name, val.name,
                          est.n_samples, singular_values)


# ---------------------------------------------------------------------------
# residuals
# ---------------------------------------------------------------------------
def residual_tests(model: LinearModel, data: IdData, max_lag: int = 25, *, initial: str = "zero") -> ResidualTests:
    """The one-step prediction errors of ``model`` on ``data`` and their whiteness and independence tests.

    Parameters
    ----------
    model : LinearModel
        Any black-box estimate.
    data : IdData
        The data (validation data, preferably).
    max_lag : int
        Largest lag of the correlations (default 25, MATLAB ``resid``'s).
    initial : {"zero", "estimate"}
        The predictor's initial conditions (default zero).

    Returns
    -------
    ResidualTests
        ``passed`` when the residuals are white and uncorrelated with the input (the verdicts of
        :func:`eha_core.identify.assessment.assess_residuals`, each with its sentence).

    Examples
    --------
    >>> import numpy as np
    >>> from eha_core.identify.polynomial import arx
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal(2000)
    >>> y = np.convolve(u, [0, 1.0, 0.5])[:2000] + 0.1 * rng.standard_normal(2000)
    >>> residual_tests(arx(IdData(y, u, 1.0), 0, 2, 1), IdData(y, u, 1.0)).passed
    True
    """
    from .assessment import assess_residuals
    from .validate import residual_analysis

    if not isinstance(data, IdData):
        raise not_allowed("data", type(data).__name__, "an IdData (eha_core.identify.blackbox.IdData)")
    if not math.isclose(getattr(model, "ts", data.ts), data.ts, rel_tol=1e-9):
        raise not_allowed("data sample time", f"{data.ts:g} s", f"the model's sample time, {model.ts:g} s")
    with np.errstate(all="ignore"):
        residuals = data.y - predict(model, data, 1, initial)
    if not np.all(np.isfinite(residuals)):
        raise not_allowed("model", getattr(model, "name", "model"), "its one-step predictor diverges on the data")
    analysis = residual_analysis(residuals, data.u, max_lag)
    assessment = assess_residuals(analysis, remedy="try higher orders or another delay nk")
    residuals.setflags(write=False)
    return ResidualTests(residuals, analysis, assessment, getattr(model, "name", "model"), data.name)
