"""``eha identify arx|armax|oe|bj|ss|process|select``: black-box models and the choice of their structure.

Like MATLAB's ``arx``, ``armax``, ``oe``, ``bj``, ``n4sid``, ``procest`` and ``arxstruc``/``selstruc``:
one model of the orders given, or a table of candidates and the one picked. Without ``--data`` the
actuator is simulated (:class:`eha_core.identify.blackbox_experiment.BlackBoxExperiment`: the
closed loop's reference r [mm] or the open loop's valve command u [V] to the position x [mm]); with
``--data`` (several are merged, as MATLAB's ``merge``) the files' t, u, y are read. The model is
validated on other data (a second experiment, ``--val-data``, or the record's last part).

The arguments are checked before anything is simulated or estimated: a typo, orders the record
cannot support or a delay longer than the record are refused at once.
"""

from __future__ import annotations

import argparse
import math
import sys

from .columns import add_columns_option, checked_columns, read_with_columns
from .common import (
    NOISE_GRAMMAR,
    check_input_file,
    check_output_file,
    json_text,
    parse_noise,
    refused,
    refused_file,
    table_text,
    tf_text,
)

#: The single-model subcommands and the orders each takes (the options), with their defaults.
ORDERS = {
    "arx": {"na": 2, "nb": 2, "nk": 1},
    "armax": {"na": 2, "nb": 2, "nc": 1, "nk": 1},
    "oe": {"nb": 2, "nf": 2, "nk": 1},
    "bj": {"nb": 2, "nc": 1, "nd": 1, "nf": 2, "nk": 1},
    "ss": {"n": 2},
    "process": {"kind": "P2D"},
}
#: What ``eha identify select`` tries by default, per structure (ARX, ss, process: the core's defaults).
SELECT_DEFAULTS = {
    "arx": {"na": "1:4", "nb": "1:4", "nk": "1:2"},
    "armax": {"na": "1:3", "nb": "1:3", "nc": "1:2", "nk": "1"},
    "oe": {"nb": "1:3", "nf": "1:3", "nk": "1"},
    "bj": {"nb": "1:2", "nc": "1:2", "nd": "1:2", "nf": "1:2", "nk": "1"},
    "ss": {"n": "1:6"},
    "process": {"kind": "P1D,P2D,P1DI,P2DI"},
}
#: The largest order an option takes, and the most candidates a selection estimates.
MAX_ORDER = 30
MAX_CANDIDATES = 200
#: Simulated records: samples at most and at least (BlackBoxExperiment's range).
MIN_SAMPLES, MAX_SAMPLES = 50, 200_000
#: The simulated record's defaults, BlackBoxExperiment's (written here: the arguments are checked before
#: the core, which loads scipy, is imported; tests/cli/test_blackbox_cli.py holds them equal).
DEFAULT_SAMPLES, DEFAULT_TS = 1500, 0.1
#: Columns read of --data, and the other names u and y go by (a closed loop's r and x).
COLUMNS = ("t", "u", "y")
ALIASES = {"u": ("r",), "y": ("x",)}
LOOPS = ("closed", "open")
#: The process models' type codes (eha_core.identify.process.KINDS, kept here so that a typo is refused before
#: scipy is imported; a test checks they agree).
KINDS = ("P1", "P1D", "P1I", "P1DI", "P2", "P2D", "P2I", "P2DI", "P2U", "P2DU", "P2IU", "P2DIU")
VALIDATIONS = ("second experiment", "split")
CRITERIA = {"bic": "bic", "aic": "aic", "fit": "validation fit", "validation fit": "validation fit",
            "validation-fit": "validation fit"}
#: The core's names of the orders -> the options (a refusal of the core names what was typed).
FIELDS = {"na": "--na", "nb": "--nb", "nc": "--nc", "nd": "--nd", "nf": "--nf", "nk": "--nk", "n": "--n",
          "kind": "--kind", "delay": "--delay", "max_lag": "--max-lag", "horizon": "--horizon"}
_HELP = {
    "arx": "ARX model A y = B u + e by least squares (like MATLAB arx)",
    "armax": "ARMAX model A y = B u + C e by the prediction-error method (like MATLAB armax)",
    "oe": "output-error model y = B/F u + e (like MATLAB oe)",
    "bj": "Box-Jenkins model y = B/F u + C/D e (like MATLAB bj)",
    "ss": "state-space model by subspace identification (like MATLAB n4sid)",
    "process": "continuous-time process model K e^(-Td s) / ... (like MATLAB procest)",
}
_ORDER_HELP = {
    "na": "order of A", "nb": "number of B coefficients (>= 1)", "nc": "order of C", "nd": "order of D",
    "nf": "order of F", "nk": "input delay in samples", "n": "number of states (>= 1)",
}


def add_parser(idsub) -> None:
    """The black-box subcommands of ``eha identify`` (``idsub``: its subparsers)."""
    for structure, orders in ORDERS.items():
        p = idsub.add_parser(structure, help=_HELP[structure],
                             description=f"{_HELP[structure][0].upper()}{_HELP[structure][1:]}. " + _DATA_WORDS)
        for name, default in orders.items():
            if name == "kind":
                p.add_argument("--kind", default=default,
                               help="the process model's type code: P1D, P2D, P1DI, P2DI (I: an integrator, the "
                                    "open loop's u to x), P2DU ... (default P2D)")
                p.add_argument("--delay", default="estimate", metavar="SECONDS|estimate",
                               help="Td: estimate (default, for a kind with D) or fixed, in seconds (0: none)")
                p.add_argument("--input-offset", default="zero", metavar="zero|estimate",
                               help="a constant input offset c, y = G (u + c): zero (default) or estimate (the "
                                    "single-rod cylinder's velocity differs with the valve's sign: in open loop "
                                    "that is an offset)")
            else:
                p.add_argument(f"--{name}", type=int, default=default,
                               help=f"{_ORDER_HELP[name]} (default {default})")
        _add_common(p)
        p.set_defaults(handler=run_model, structure=structure, fields=FIELDS, inputs=_INPUTS)
    s = idsub.add_parser("select", help="structure and order selection: a table of candidates and the one picked "
                                        "(like MATLAB arxstruc/selstruc)",
                         description="Estimate every candidate on the estimation data and pick one by the fit "
                                     "on validation data (default: the fewest parameters whose validation loss "
                                     "the data cannot tell from the best's), BIC or AIC. Orders are ranges: 1:4, 1,3 "
                                     "or 2. " + _DATA_WORDS)
    s.add_argument("--structure", default="arx", help="arx (default), armax, oe, bj, ss or process")
    for name in ("na", "nb", "nc", "nd", "nf", "nk", "n"):
        s.add_argument(f"--{name}", metavar="RANGE",
                       help=f"{_ORDER_HELP[name]}: FROM:TO, a list 1,2,4, or one value")
    s.add_argument("--kind", metavar="KINDS", help="process: the type codes tried, e.g. P1D,P2D (default "
                                                   "P1D,P2D,P1DI,P2DI)")
    s.add_argument("--criterion", default="fit",
                   help="how the model is picked: fit (default; the best fit on the validation data, as those "
                        "data can tell it), bic or aic (the least BIC or AIC on the estimation data)")
    _add_common(s)
    s.set_defaults(handler=run_select, fields=FIELDS, inputs=_INPUTS)


_DATA_WORDS = ("Without --data the actuator is simulated (--loop closed: the reference r [mm] to the position "
               "x [mm] under the P controller; open: the valve command u [V] to x) and validated on a second "
               "experiment; with --data the files' t, u, y are read (several are merged) and validated on "
               "--val-data or the record's last half.")
#: What a simulation or an estimate that fails may follow from, the likeliest first.
_INPUTS = ("--data", "--val-data", "--samples", "--ts", "--noise", "--loop")


def _add_common(p) -> None:
    p.add_argument("--data", action="append", metavar="FILE",
                   help="a CSV or .mat file with columns t, u, y (or t, r, x), uniformly sampled; repeat it to "
                        "merge experiments of one sample time")
    p.add_argument("--val-data", metavar="FILE", help="validation data, a file like --data (with --data)")
    add_columns_option(p, "t, u, y (u may be a closed loop's reference r, y its position x)")
    p.add_argument("--loop", default="closed", help="simulated record: closed (r to x, default) or open (u to x)")
    p.add_argument("--samples", type=int, default=DEFAULT_SAMPLES,
                   help=f"simulated record: samples of each experiment ({MIN_SAMPLES} to {MAX_SAMPLES}, default "
                        f"{DEFAULT_SAMPLES})")
    p.add_argument("--ts", type=float, default=None,
                   help=f"simulated record: sample time [s] (default {DEFAULT_TS:g})")
    p.add_argument("--noise", default="x=0.01mm", metavar="x=SIGMA[UNIT]",
                   help=f"simulated record: the position sensor's noise, {NOISE_GRAMMAR} (x only; default x=0.01mm)")
    p.add_argument("--experiments", type=int, default=1,
                   help="simulated record: experiments merged for the estimation (1 to 5, default 1; seeds "
                        "seed, seed + 1, ...), validated on one more")
    p.add_argument("--seed", type=int, default=0, help="simulated record: seed (the validation experiment's is "
                                                       "seed + 1; default 0)")
    p.add_argument("--validation", default=None,
                   help="'second experiment' (default when simulated) or split (the record's last half; the "
                        "default with --data and no --val-data)")
    p.add_argument("--detrend", action=argparse.BooleanOptionalAction, default=None,
                   help="remove each experiment's means first (default, but for the simulated open loop, whose "
                        "position integrates: its mean is no operating point; --no-detrend keeps them: a linear model "
                        "then has to explain the offsets too)")
    p.add_argument("--horizon", default="inf",
                   help="the fits' horizon: inf (simulation, default) or k (k-step prediction)")
    p.add_argument("--initial", default="zero",
                   help="initial conditions of the fits, and of the estimate for ss and process: zero (default) or "
                        "estimate (each experiment's free response fitted)")
    p.add_argument("--max-lag", type=int, default=25, help="largest lag of the residual tests (default 25)")
    p.add_argument("--json", action="store_true", help="print JSON (default: text)")
    p.add_argument("--out", metavar="FILE.json", help="write the model (parameters, covariance, G, H) as JSON")


# ---------------------------------------------------------------------------
# checks (before anything heavy is imported)
# ---------------------------------------------------------------------------
def _choice(option: str, value, allowed) -> None:
    if value not in allowed:
        raise refused(option, value, f"use {', '.join(allowed[:-1])} or {allowed[-1]}", value_text=str(value))


def _horizon(text: str):
    t = str(text).strip().lower()
    if t in ("inf", "infinity", "simulation"):
        return None
    try:
        k = int(t)
    except ValueError:
        k = 0
    if k < 1:
        raise refused("--horizon", text, "use inf (simulation) or a whole number of steps >= 1")
    return k


def _size(orders: dict) -> tuple[int, int]:
    """Parameters and longest lag of a model of these orders (as the estimators count them)."""
    if "n" in orders:
        # n4sid: 3 n parameters (a, b, c); its horizon of n + 1 block rows needs 6 (n + 1) - 1 samples
        n = orders["n"]
        return 3 * n, 3 * n + 5
    if "kind" in orders:
        kind = orders["kind"]
        return 1 + int(kind[1]) + ("D" in kind), 0
    g = {k: orders.get(k, 0) for k in ("na", "nb", "nc", "nd", "nf", "nk")}
    return (g["na"] + g["nb"] + g["nc"] + g["nd"] + g["nf"],
            max(g["na"], g["nb"] + g["nk"] - 1, g["nc"], g["nd"], g["nf"]))


def _check_orders(orders: dict, typed: dict) -> None:
    """Each order a whole number in its range (the record's length is checked by :func:`_check_fits`)."""
    for name, value in orders.items():
        if name == "kind":
            continue
        lo = 1 if name in ("nb", "n") else 0
        # a delay is bounded by the record (checked with it), an order by what an estimate can hold
        hi = MAX_SAMPLES if name == "nk" else MAX_ORDER
        if not lo <= value <= hi:
            raise refused(f"--{name}", value, f"use a whole number from {lo} to {hi}",
                          value_text=typed.get(f"--{name}", str(value)))


def _check_kind(option: str, text: str) -> str:
    kind = str(text).strip().upper()
    if kind not in KINDS:
        raise refused(option, text, f"use a process type code: {', '.join(KINDS)}")
    return kind


def _check_fits(orders: dict, shortest: int, where: str, typed: dict, option_text=None) -> None:
    """Refuse orders that ``shortest`` samples (the shortest estimation experiment) cannot support."""
    if orders.get("nk", 0) >= shortest:
        raise refused("--nk", orders["nk"], f"the input delay must be shorter than {where} ({shortest} samples)",
                      value_text=typed.get("--nk", str(orders["nk"])))
    n_params, lag = _size(orders)
    if "n" in orders and shortest < n_params + lag:
        raise refused("--n", orders["n"], f"order {orders['n']} needs a Hankel horizon of {orders['n'] + 1} block "
                                          f"rows, so at least {n_params + lag} samples, and {where} has {shortest}: "
                                          "lower the order or give a longer record",
                      value_text=typed.get("--n", str(orders["n"])))
    if shortest < n_params + lag:
        name = max((k for k in orders if k != "kind"), key=lambda k: orders[k], default="kind")
        raise refused(f"--{name}", orders[name],
                      f"{n_params} parameters and a longest lag of {lag} samples need at least {n_params + lag} "
                      f"samples and {where} has {shortest}: lower the orders or give a longer record",
                      value_text=typed.get(f"--{name}", str(orders[name])))


def _delay(args, record_s: float | None):
    """``--delay`` as procest takes it (True: estimate; seconds), checked against the record's length."""
    text = str(args.delay).strip()
    if text == "estimate":
        return True
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value >= 0):
        raise refused("--delay", args.delay, "use estimate or a delay in seconds >= 0")
    if record_s is not None and value >= record_s:
        raise refused("--delay", args.delay, f"a delay must be shorter than the record ({record_s:g} s)")
    return value


def _check_sources(args, data: list, validation) -> None:
    """The record's options: files (their sample time is theirs; merged ones are validated on another) or a
    simulation (its length, sample time and experiments)."""
    if data:
        if args.ts is not None:
            raise refused("--ts", args.ts, "the sample time is read from the file's t", context="with --data")
        if validation == "second experiment" and not args.val_data:
            raise refused("--validation", args.validation, "give the second experiment with --val-data",
                          context="with --data")
        if len(data) > 1 and not args.val_data:
            if args.validation is None:
                raise refused_file("--data", data[-1], "merged experiments are not split for validation: give "
                                                       "the validation data with --val-data")
            raise refused("--validation", args.validation, "merged experiments are not split: give --val-data",
                          context="with several --data")
    else:
        if not MIN_SAMPLES <= args.samples <= MAX_SAMPLES:
            raise refused("--samples", args.samples, f"use a whole number from {MIN_SAMPLES} to {MAX_SAMPLES}")
        if args.ts is not None and not (math.isfinite(args.ts) and 1e-4 <= args.ts <= 1.0):
            raise refused("--ts", args.ts, "use a sample time from 0.0001 to 1 s")
        if not 1 <= args.experiments <= 5:
            raise refused("--experiments", args.experiments, "use a whole number from 1 to 5")
        if args.experiments > 1 and validation == "split":
            raise refused("--validation", args.validation, "merged experiments are validated on a second "
                                                           "experiment, not split", context="with --experiments")


def _check_common(args) -> dict:
    """The data options, checked: what the record will be, without reading or simulating it."""
    if args.seed < 0:
        raise refused("--seed", args.seed, "use a whole number >= 0")
    _choice("--loop", args.loop, LOOPS)
    _choice("--initial", args.initial, ("zero", "estimate"))
    horizon = _horizon(args.horizon)
    if not 1 <= args.max_lag <= 1000:
        raise refused("--max-lag", args.max_lag, "use a whole number from 1 to 1000")
    validation = args.validation
    if validation is not None:
        validation = " ".join(validation.replace("-", " ").split())
        _choice("--validation", validation, VALIDATIONS)
    data = list(args.data or [])
    for path in data:
        check_input_file("--data", path)
    check_input_file("--val-data", args.val_data)
    check_output_file("--out", args.out)
    if args.val_data and not data:
        raise refused_file("--val-data", args.val_data, "it validates a model of measured data: give --data too")
    if args.val_data and validation == "split":
        raise refused("--validation", args.validation, "--val-data is the validation data", context="with --val-data")
    _check_sources(args, data, validation)
    noise = parse_noise(args.noise, "--noise", signals=("x",), bare="x")
    if noise.get("x", 0.0) > 0.01:
        raise refused("--noise", args.noise, "σ of x at most 0.01 m (10 mm)")
    columns = checked_columns(args, COLUMNS)
    split = validation == "split" or (data and not args.val_data)
    # without --data the record's length is known now: the estimation experiment's samples
    shortest = None if data else (args.samples if not split else int(round(0.5 * args.samples)))
    return {"horizon": horizon, "validation": validation or ("split" if split else "second experiment"),
            "data": data, "noise_x": noise.get("x", 0.0), "columns": columns, "shortest": shortest,
            "ts": args.ts or DEFAULT_TS}


# ---------------------------------------------------------------------------
# the records
# ---------------------------------------------------------------------------
def _read(path: str, option: str, columns: dict):
    from eha_core.data import read_columns, sample_time
    from eha_core.identify.blackbox import IdData

    def read(mapping, names=COLUMNS):
        cols = read_columns(path, names, name=option, min_rows=10, mapping=mapping)
        return dict(zip(COLUMNS, (cols[n] for n in names), strict=True))

    cols = read_with_columns(read, path, COLUMNS, columns, aliases=ALIASES,
                             also=(lambda: read(None, ("t", "r", "x")), "t, r, x"), option=option)
    ts = sample_time(cols["t"], name=option, path=path)
    return IdData(cols["y"], cols["u"], ts, name=path)


def _records(args, checked: dict):
    """``(estimation, validation, source)``: the files of --data (merged) and --val-data, or the simulated
    experiment."""
    from eha_core.identify.blackbox import merge

    if checked["data"]:
        datas = [_read(p, "--data", checked["columns"]) for p in checked["data"]]
        for path, d in zip(checked["data"][1:], datas[1:], strict=True):
            if not math.isclose(d.ts, datas[0].ts, rel_tol=1e-6):
                raise refused_file("--data", path, f"its sample time is {d.ts:g} s and {checked['data'][0]}'s "
                                                   f"{datas[0].ts:g} s: merged experiments need one sample time")
        est = merge(*datas, name=" + ".join(checked["data"])) if len(datas) > 1 else datas[0]
        if args.val_data:
            val = _read(args.val_data, "--val-data", checked["columns"])
            if not math.isclose(val.ts, est.ts, rel_tol=1e-6):
                raise refused_file("--val-data", args.val_data, f"its sample time is {val.ts:g} s and the "
                                                                f"estimation data's {est.ts:g} s")
        else:
            est, val = est.split(0.5)
        source = "data: " + est.name
    else:
        from eha_core.identify.blackbox_experiment import BlackBoxExperiment

        exp = BlackBoxExperiment(loop=args.loop, n_samples=args.samples, ts=checked["ts"],
                                 noise_x=checked["noise_x"], seed=args.seed, validation=checked["validation"],
                                 n_experiments=args.experiments)
        est, val = exp.records()
        merged = "" if args.experiments == 1 else f" x {args.experiments} experiments merged"
        source = (f"simulated {args.loop} loop, {exp.input_name} to {exp.output_name}, {args.samples} samples"
                  f"{merged} at {checked['ts']:g} s, seed {args.seed}")
    detrend = args.detrend if args.detrend is not None else bool(checked["data"]) or args.loop != "open"
    if detrend:
        est, val = est.detrended(), val.detrended()
        source += ", means removed"
    return est, val, source


def _shortest(est) -> tuple[int, str]:
    n = min(y.size for y, _u in est.segments())
    return n, ("the estimation record" if est.n_experiments == 1 else "the shortest estimation experiment")


# ---------------------------------------------------------------------------
# one model
# ---------------------------------------------------------------------------
def _estimate(structure: str, est, orders: dict, delay, initial: str, input_offset: str = "zero"):
    # ARX takes its first samples as initial conditions; the others start from rest or estimate them
    if structure == "ss":
        from eha_core.identify.subspace import n4sid

        return n4sid(est, orders["n"], initial=initial)
    if structure == "process":
        from eha_core.identify.process import procest

        return procest(est, orders["kind"], delay=delay, initial=initial, input_offset=input_offset)
    from eha_core.identify import polynomial

    if structure == "arx":
        return polynomial.arx(est, **orders)
    return getattr(polynomial, structure)(est, **orders, initial=initial)


def run_model(args) -> int:
    structure = args.structure
    orders = {k: getattr(args, k) for k in ORDERS[structure]}
    _check_orders(orders, args.typed)
    checked = _check_common(args)
    record_s = None if checked["shortest"] is None else (checked["shortest"] - 1) * checked["ts"]
    delay = _delay(args, record_s) if structure == "process" else None
    offset = getattr(args, "input_offset", "zero")
    _choice("--input-offset", offset, ("zero", "estimate"))
    if structure == "process":
        orders["kind"] = _check_kind("--kind", args.kind)
    if checked["shortest"] is not None:
        _check_fits(orders, checked["shortest"], "the estimation record", args.typed)

    est, val, source = _records(args, checked)
    shortest, where = _shortest(est)
    _check_fits(orders, shortest, where, args.typed)
    if structure == "process" and delay is not True:
        _delay(args, (shortest - 1) * est.ts)
    model = _estimate(structure, est, orders, delay, args.initial, offset)
    report = _report(model, est, val, checked["horizon"], args.initial, args.max_lag)
    return _output(args, model, report, source)


def _report(model, est, val, horizon, initial, max_lag) -> dict:
    """The fits on estimation and validation data and the residual tests, as the command prints them."""
    import numpy as np

    from eha_core.identify.blackbox import compare
    from eha_core.identify.selection import residual_tests

    out = {"estimation": None, "validation": None, "residual_tests": None}
    if not np.all(np.isfinite(np.asarray(model.params, float))):
        return out
    with np.errstate(all="ignore"):
        fit_est, fit_val = compare(model, est, horizon, initial), compare(model, val, horizon, initial)
    out["estimation"] = _fit_dict(fit_est, est)
    out["validation"] = _fit_dict(fit_val, val)
    try:
        tests = residual_tests(model, val, min(max_lag, val.n_samples - 1))
    except ValueError as exc:                   # a predictor that diverges, residuals that are all zero
        out["residual_tests"] = {"passed": None, "problem": str(exc)}
        return out
    out["residual_tests"] = {
        "data": val.name, "passed": tests.passed, "horizon": "1-step prediction errors",
        "whiteness": {"passed": tests.whiteness.passed, "sentence": tests.whiteness.sentence},
        "independence": {"passed": tests.independence.passed, "sentence": tests.independence.sentence}}
    return out


def _fit_dict(comparison, data) -> dict:
    return {"data": data.name, "fit_percent": comparison.fit_percent, "label": comparison.label,
            "horizon": None if comparison.horizon is None else int(comparison.horizon),
            "initial": comparison.initial}


def _output(args, model, report, source, *, prefix: list[str] | None = None, table=None) -> int:
    out = model.to_dict()
    out.update({"source": source, "validation": report["validation"], "estimation_fit": report["estimation"],
                "residual_tests": report["residual_tests"]})
    if args.out:
        with open(args.out, "w", encoding="utf-8") as fh:
            fh.write(json_text(model.to_dict()) + "\n")
    ok = bool(model.success)
    if args.json:
        print(json_text(out if table is None else {**table.to_dict(), "best_model": out}))
        return 0 if ok else 1
    lines = list(prefix or []) + [f"{model.name} from {source}"] + model_lines(model) + [""]
    lines += param_table(model) + [""]
    if report["estimation"] is not None:
        lines.append(f"estimation data ({report['estimation']['data']}): {report['estimation']['label']}")
        lines.append(f"validation data ({report['validation']['data']}): {report['validation']['label']}")
    if model.fit is not None:
        lines.append(f"the estimator's own fit on the estimation data: {model.fit.label}")
    c = model.criteria
    lines.append(f"loss {c.loss:.6g}, AIC {c.aic:.6g}, BIC {c.bic:.6g}, FPE {c.fpe:.6g} ({c.n_params} parameters, "
                 f"{c.n_samples} prediction errors)")
    tests = report["residual_tests"]
    if tests is not None:
        if tests["passed"] is None:
            lines.append(f"residual tests: not made ({tests['problem']})")
        else:
            lines.append(f"residual tests on the validation data ({tests['horizon']}):")
            for key in ("whiteness", "independence"):
                mark = "✓" if tests[key]["passed"] else "✗"
                lines.append(f"  {mark} {key}: {tests[key]['sentence']}")
    if args.out:
        lines.append(f"model written to {args.out}")
    print("\n".join(lines))
    if not ok:
        print(f"eha identify {model.structure if table is None else 'select'}: warning: {model.message}",
              file=sys.stderr)
    return 0 if ok else 1


def _q_poly(coeffs, start: int = 0) -> str:
    """``1 - 1.5 q^-1 + 0.7 q^-2`` of coefficients in ascending powers of ``q^-1``."""
    terms = []
    for power, c in enumerate(coeffs, start=start):
        c = float(c)
        if c == 0.0:
            continue
        q = "" if power == 0 else (" q^-1" if power == 1 else f" q^-{power}")
        mag = f"{abs(c):.6g}"
        body = q.strip() if mag == "1" and q else mag + q
        terms.append(("-" if c < 0 else "") + body if not terms else (" - " if c < 0 else " + ") + body)
    return "".join(terms) or "0"


def model_lines(model) -> list[str]:
    """The model as text: its polynomials in ``q^-1``, its matrices, or its ``G(s)``."""
    import numpy as np

    if model.structure in ("arx", "armax", "oe", "bj"):
        free = {"arx": "AB", "armax": "ABC", "oe": "BF", "bj": "BCDF"}[model.structure]
        return [f"  {p}(q) = {_q_poly(getattr(model, p))}" for p in free]
    if model.structure == "ss":
        lines = ["  x(t+1) = A x(t) + B u(t) + K e(t),  y(t) = C x(t) + D u(t) + e(t)"]
        for name in ("A", "B", "C", "D", "K"):
            text = np.array2string(np.asarray(getattr(model, name)), precision=5, suppress_small=True)
            lines.append(f"  {name} = " + text.replace("\n", "\n" + " " * (len(name) + 5)))
        sv = getattr(model, "singular_values", None)
        if sv is not None:
            lines.append("  singular values: " + " ".join(f"{v:.4g}" for v in np.asarray(sv)[:10]))
        return lines
    if model.structure == "process":
        from eha_core.identify.process import process_tf

        num, den = process_tf(model.kind, model.values)
        td = float(model.values.get("Td", 0.0))
        return [f"  {tf_text(num, den, 'G(s)')}" + (f" e^(-{td:.6g} s)" if td else ""),
                f"  discrete at {model.ts:g} s: G(q) = ({_q_poly(model.discrete_num)}) / "
                f"({_q_poly(model.discrete_den)})"]
    gb, ga = model.g_poly()
    return [f"  G(q) = ({_q_poly(gb)}) / ({_q_poly(ga)})"]


def param_table(model) -> list[str]:
    """The parameters with their standard errors and 95 % intervals."""
    import numpy as np

    lo, hi = model.intervals(0.95)
    std = model.param_std
    rows = []
    for k, name in enumerate(model.param_names):
        finite = np.isfinite(std[k]) and np.isfinite(lo[k])
        rows.append([name, f"{model.params[k]:.6g}", f"{std[k]:.3g}" if finite else "—",
                     f"[{lo[k]:.6g}, {hi[k]:.6g}]" if finite else "—"])
    return ["  " + line for line in table_text(["parameter", "estimate", "std error", "95 % interval"], rows,
                                                align="lrrl")]


# ---------------------------------------------------------------------------
# selection
# ---------------------------------------------------------------------------
def _range(option: str, text: str, minimum: int, maximum: int = MAX_ORDER) -> list[int]:
    """``1:4``, ``1,3`` or ``2`` as the whole numbers it names."""
    values = []
    for part in str(text).split(","):
        lo, colon, hi = part.partition(":")
        try:
            a = int(lo)
            b = int(hi) if colon else a
        except ValueError:
            raise refused(option, text, "use a range FROM:TO, a list 1,2,4 or one whole number") from None
        if not (minimum <= a <= b <= maximum):
            raise refused(option, text, f"use whole numbers from {minimum} to {maximum}, FROM <= TO")
        values.extend(range(a, b + 1))
    return sorted(set(values))


def _candidates(args, structure: str) -> list[dict]:
    names = list(SELECT_DEFAULTS[structure])
    for other in ("na", "nb", "nc", "nd", "nf", "nk", "n", "kind"):
        value = getattr(args, other)
        if value is not None and other not in names:
            raise refused(f"--{other}", value, f"{structure} has no {other}; its orders are "
                                               + ", ".join(f"--{n}" for n in names))
    if structure == "process":
        text = args.kind or SELECT_DEFAULTS["process"]["kind"]
        return [{"kind": _check_kind("--kind", k)} for k in text.split(",") if k.strip()] or \
            [{"kind": _check_kind("--kind", text)}]
    ranges = {n: _range(f"--{n}", getattr(args, n) or SELECT_DEFAULTS[structure][n], 1 if n in ("nb", "n") else 0,
                        MAX_SAMPLES if n == "nk" else MAX_ORDER) for n in names}
    count = math.prod(len(v) for v in ranges.values())
    if count > MAX_CANDIDATES:
        widest = max(names, key=lambda n: len(ranges[n]))
        raise refused(f"--{widest}", getattr(args, widest) or SELECT_DEFAULTS[structure][widest],
                      f"the ranges make {count} candidates; at most {MAX_CANDIDATES}")
    import itertools

    return [dict(zip(names, combo, strict=True)) for combo in itertools.product(*(ranges[n] for n in names))]


def run_select(args) -> int:
    structure = str(args.structure).strip().lower()
    if structure not in SELECT_DEFAULTS:
        raise refused("--structure", args.structure, "use arx, armax, oe, bj, ss or process")
    criterion = CRITERIA.get(str(args.criterion).strip().lower())
    if criterion is None:
        raise refused("--criterion", args.criterion, "use bic, aic or fit (the validation fit)")
    candidates = _candidates(args, structure)
    checked = _check_common(args)
    if checked["shortest"] is not None:
        for c in candidates:
            _check_fits(c, checked["shortest"], "the estimation record", args.typed)

    est, val, source = _records(args, checked)
    shortest, where = _shortest(est)
    for c in candidates:
        _check_fits(c, shortest, where, args.typed)
    if structure in ("ss", "process") and args.initial == "estimate":
        candidates = [{**c, "initial": "estimate"} for c in candidates]
    from eha_core.identify.selection import select_structure

    table = select_structure(est, val, candidates, structure=structure, criterion=criterion,
                             horizon=checked["horizon"], initial=args.initial)
    lines = select_lines(table)
    if table.best_model is None:
        if args.json:
            print(json_text(table.to_dict()))
        else:
            print("\n".join(lines))
        print("eha identify select: warning: no candidate succeeded; see each row's message (--json)",
              file=sys.stderr)
        return 1
    report = _report(table.best_model, est, val, checked["horizon"], args.initial, args.max_lag)
    return _output(args, table.best_model, report, source, prefix=lines + [""], table=table)


def select_lines(table) -> list[str]:
    """The selection table as text: one row per candidate, the picked one marked."""
    import numpy as np

    from eha_core.identify.blackbox import horizon_words, initial_words

    rows = []
    for i, r in enumerate(table.rows):
        rows.append(["*" if i == table.best_index else "", r.name, r.n_params, f"{r.loss:.5g}", f"{r.aic:.6g}",
                     f"{r.bic:.6g}", f"{r.validation_fit:.2f}" if np.isfinite(r.validation_fit) else "—",
                     "" if r.success else "failed"])
    lines = [f"{len(table.rows)} {table.structure.upper()} candidates estimated on {table.estimation_name}; "
             f"loss, AIC and BIC of their one-step prediction errors there; validation fit on "
             f"{table.validation_name} ({horizon_words(table.horizon)}, {initial_words(table.initial)})"]
    lines += table_text(["", "model", "parameters", "loss", "AIC", "BIC", "validation fit [%]", ""], rows,
                        align="llrrrrrl")
    if table.singular_values is not None:
        lines.append("singular values: " + " ".join(f"{v:.4g}" for v in table.singular_values))
    criterion = {"bic": "the least BIC", "aic": "the least AIC",
                 "validation fit": "the best validation fit (the fewest parameters within the data's uncertainty)"}
    lines.append(f"picked by {criterion[table.criterion]}: " + (table.best.name if table.best else "none succeeded"))
    return lines

