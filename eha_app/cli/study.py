"""``eha study lse|tf|greybox|grading``: one experiment repeated over many noise seeds (:mod:`eha_core.study`),
or a class's hand-ins graded (:mod:`eha_core.grading`).

Shows whether an estimator's standard errors are honest: per parameter, the
mean and spread of the estimates over the seeds, the mean reported standard
error, and the coverage (the fraction of seeds whose 95 % interval holds the
nominal value). The arguments are checked before the estimators (scipy,
numba) are imported: a typo is refused at once.
"""

from __future__ import annotations

import math
import sys

from eha_core.errors import FieldError

from .common import (
    NOISE_GRAMMAR,
    PARAM_HELP,
    Parser,
    UsageError,
    as_typed,
    check_range,
    interrupt_cancels,
    json_text,
    parse_noise,
    parse_params,
    refused,
    table_text,
)
from .identify import MAX_LSE_T_END as MAX_T_END
from .identify import MIN_LSE_T_END as MIN_T_END

#: The sensors the least squares reads (for --noise).
LSE_SENSORS = ("x", "v", "p1", "p2")


def add_parser(sub) -> None:
    from eha_core.signals import SIGNAL_GRAMMAR
    from eha_core.study import DEFAULT_WORKERS, MAX_SEEDS, MAX_WORKERS

    st = sub.add_parser("study", help="repeat an identification over many noise seeds: spread and coverage")
    stsub = st.add_subparsers(dest="method", metavar="METHOD", parser_class=Parser)
    st.set_defaults(handler=_missing_method)

    def common(p):
        p.add_argument("--seeds", type=int, required=True, help=f"number of runs, 1 to {MAX_SEEDS}")
        p.add_argument("--first-seed", type=int, default=0, help="seed of the first run (default 0); run i has "
                                                                 "seed first + i")
        p.add_argument("--workers", type=int, default=DEFAULT_WORKERS,
                       help=f"threads, 1 to {MAX_WORKERS} (default {DEFAULT_WORKERS})")
        p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE", help=PARAM_HELP)
        p.add_argument("--json", action="store_true",
                       help="print JSON: every seed's estimates, and coverage, mean, std, nominal, n_seeds, settings")

    le = stsub.add_parser("lse", help="least squares (eqs. 15-18) over many disturbance seeds",
                          description="Least squares repeated over seeds: the nonlinear model under the "
                                      "disturbance, u = 6 sin(4 pi t) for 5 s at 1 kHz; seed k draws the noise as "
                                      "eha identify lse --seed k.", epilog=SIGNAL_GRAMMAR)
    common(le)
    le.add_argument("--disturbance", default="white:1000",
                    help="load disturbance d(t) as signal text, default white:1000 (the paper's white noise); a "
                         "noise term takes the run's seed, so give it none")
    le.add_argument("--disturbance-model", default="constant",
                    help="constant (the paper's d0) or harmonic[:FREQ_HZ] (d0 + a sinusoid)")
    le.add_argument("--model", default="nonlinear", help="the plant: nonlinear (the only one the least squares' "
                                                         "equations hold for)")
    le.add_argument("--noise", action="append", default=[], metavar="SIGNAL=SIGMA[UNIT],...",
                    help=f"the sensors' noise, {NOISE_GRAMMAR}; repeatable (default none), e.g. "
                         "x=0.01mm,p=0.05MPa")
    le.add_argument("--t-end", type=float, default=5.0, help=f"record length [s] (default 5, {MIN_T_END:g} to "
                                                             f"{MAX_T_END:g})")
    le.add_argument("--estimator", default="ls",
                    help="ls (the paper's least squares; the default) or iv (instrumental variables)")
    le.add_argument("--intervals", default=None,
                    help="newey-west or ewc (equal-weighted cosines); default newey-west for ls, ewc for iv")
    le.set_defaults(handler=run_study_command, kind="lse")

    tf = stsub.add_parser("tf", help="transfer-function estimate (eqs. 19-25) over many excitation seeds",
                          description="The paper's closed-loop experiment repeated over seeds: seed k draws the "
                                      "idinput excitation (as eha identify tf --seed k) and the position noise. "
                                      "Nominal values: the linearised H(s) of eq. 24, the truth for the linear "
                                      "plant, a reference for the nonlinear one.")
    common(tf)
    tf.add_argument("--model", default="nonlinear", help="the plant in the loop: nonlinear (default) or linear")
    tf.add_argument("--noise", default="x=0.1mm", metavar="x=SIGMA[UNIT]",
                    help=f"the position sensor's noise, {NOISE_GRAMMAR}; of x only, the one signal the "
                         "experiment records (default x=0.1mm; a plain number is x in m, e.g. 1e-4)")
    tf.set_defaults(handler=run_study_command, kind="tf")

    gb = stsub.add_parser("greybox", help="grey-box estimate over many noise seeds: coverage and Cramer-Rao bound",
                          description="The grey-box estimate repeated over seeds: the nonlinear plant (--param), "
                                      "u = 6 sin(4 pi t), a load 5000 sin(2 pi t) N known to the model, white noise "
                                      "--snr-db below each measured signal's standard deviation; each seed starts "
                                      "from the paper's values. Per parameter: mean, std, bias in standard errors, "
                                      "coverage of the 95 % intervals, the Cramer-Rao bound and std / CRB.")
    common(gb)
    gb.add_argument("--params", default="M,B,Af,beta_e", metavar="NAMES",
                    help="the parameters estimated, comma-separated (default M,B,Af,beta_e)")
    gb.add_argument("--measured", default="x,p1,p2", metavar="SIGNALS",
                    help="the signals measured and compared, of x, v, p1, p2 (default x,p1,p2)")
    gb.add_argument("--snr-db", type=float, default=30.0, help="signal-to-noise ratio of every measured signal [dB] "
                                                              "(default 30)")
    gb.add_argument("--t-end", type=float, default=5.0, help="record length [s] (default 5)")
    gb.set_defaults(handler=run_greybox_study_command, kind="greybox")

    gr = stsub.add_parser("grading", help="is the lab's grading fair? many students, each their own actuator",
                          description="Students of an exercise (eha exercise new's defaults, or --exercise), each "
                                      "identifying their own actuator by one route with the page's default "
                                      "experiment or a sound one, judged by the exercise's grading. Prints, per "
                                      "route: the honest values refused, those the record does not determine to "
                                      "the tolerance, the hand-ins accepted whole, a neighbour's values refused, "
                                      "the score of three sprayed guesses, and the acceptance per parameter.")
    gr.add_argument("--students", type=int, default=200, help="students per route, 2 to 5000 (default 200); "
                                                              "student i's noise seed is i")
    gr.add_argument("--route", default="all", help="lse, frequency, greybox or all (default)")
    gr.add_argument("--experiment", default="both", help="default (the page's default run), sound, or both "
                                                         "(default)")
    gr.add_argument("--exercise", metavar="FILE", help="an exercise file to grade by (its secret draws the "
                                                       "students; default: eha exercise new's defaults)")
    gr.add_argument("--workers", type=int, default=DEFAULT_WORKERS,
                    help=f"threads, 1 to {MAX_WORKERS} (default {DEFAULT_WORKERS})")
    gr.add_argument("--json", action="store_true", help="print one JSON object per route and experiment")
    gr.set_defaults(handler=run_grading_study_command, kind="grading")


def _missing_method(args) -> int:
    raise UsageError("study needs a METHOD: lse, tf, greybox or grading (eha study --help tells more)")


def run_grading_study_command(args) -> int:
    from eha_core.grading import EXPERIMENTS, ROUTES
    from eha_core.study import MAX_WORKERS

    routes = list(ROUTES) if args.route == "all" else [args.route]
    if any(r not in ROUTES for r in routes):
        raise refused("--route", args.route, f"one of {', '.join(ROUTES)} or all")
    experiments = ["default", "sound"] if args.experiment == "both" else [args.experiment]
    if any(e not in ("default", "sound") for e in experiments):
        raise refused("--experiment", args.experiment, "default, sound or both")
    if not 2 <= args.students <= 5000:
        raise refused("--students", args.students, "a whole number in 2-5000 (each student is compared with the next)")
    if not 1 <= args.workers <= MAX_WORKERS:
        raise refused("--workers", args.workers, f"a whole number in 1-{MAX_WORKERS}")
    exercise = None
    if args.exercise:
        from eha_core.exercise import Exercise

        from .common import check_input_file

        check_input_file("--exercise", args.exercise)
        try:
            exercise = Exercise.load(args.exercise)
        except FieldError as exc:
            raise refused("--exercise", args.exercise, exc.what) from None
    from eha_core.cancel import CancelToken
    from eha_core.grading import GradingStudyConfig, run_grading_study

    token = CancelToken()
    for route in routes:
        for experiment in experiments:
            config = GradingStudyConfig(route, n_students=args.students, experiment=experiment, exercise=exercise)
            res = _with_progress(lambda progress, c=config: run_grading_study(
                c, workers=args.workers, progress=progress, cancel=token), args.students, args.json, token)
            if args.json:
                print(json_text(res.to_dict()))
            else:
                print(f"# {route}, {experiment}: {EXPERIMENTS[route][experiment]}")
                print(res.summary(), f"time={res.time_s:.0f}s", flush=True)
    return 0


def _sensor_noise(items) -> dict[str, float]:
    """The least squares' ``--noise`` (repeatable; a later σ of a signal replaces an earlier one)."""
    noise = {}
    for item in items:
        noise.update(parse_noise(item, signals=LSE_SENSORS))
    return noise


def _position_noise(text: str) -> float:
    """The frequency experiment's ``--noise``: σ of x [m] (a plain number, the spelling before the one
    grammar, is x in m)."""
    return parse_noise(text, signals=("x",), bare="x").get("x", 0.0)


#: Core names of StudyConfig's fields -> the options that set them (for its messages).
_OPTIONS = {"disturbance": "--disturbance", "disturbance_model": "--disturbance-model", "t_end": "--t-end",
            "estimator": "--estimator", "intervals": "--intervals"}


def _config(args):
    """The checked :class:`~eha_core.study.StudyConfig` (light imports only: no scipy yet)."""
    from eha_core.experiments import FrequencyExperiment
    from eha_core.identify.disturbance import parse_disturbance_model
    from eha_core.signals import parse_signal
    from eha_core.study import MAX_SEEDS, MAX_WORKERS, StudyConfig

    check_range("--seeds", args.seeds, 1, MAX_SEEDS, "seeds")
    check_range("--workers", args.workers, 1, MAX_WORKERS, "threads")
    check_range("--first-seed", args.first_seed, 0, 2**32 - 1 - MAX_SEEDS)
    if args.kind == "lse":
        if args.model != "nonlinear":
            raise refused("--model", args.model, "the least squares identifies the nonlinear model's parameters "
                          "(eqs. 15-18); use nonlinear, or eha study tf for the linear plant", value_text=args.model)
        if not (math.isfinite(args.t_end) and MIN_T_END <= args.t_end <= MAX_T_END):
            raise refused("--t-end", args.t_end, f"use a record length in [{MIN_T_END:g}, {MAX_T_END:g}] s")
        model, freq = parse_disturbance_model(args.disturbance_model, name="--disturbance-model")
        parse_signal(args.disturbance, name="--disturbance")
        kwargs = {"disturbance": args.disturbance, "disturbance_model": model, "disturbance_freq_hz": freq,
                  "sensor_noise": _sensor_noise(args.noise), "t_end": args.t_end, "estimator": args.estimator,
                  "intervals": args.intervals}
    else:
        if args.model not in ("nonlinear", "linear"):
            raise refused("--model", args.model, "use nonlinear or linear", value_text=args.model)
        kwargs = {"experiment": FrequencyExperiment(model=args.model), "noise_m": _position_noise(args.noise)}
    try:
        return StudyConfig(args.kind, n_seeds=args.seeds, first_seed=args.first_seed, **kwargs)
    except FieldError as exc:
        # the core names its field; the user typed the option
        raise UsageError(as_typed(exc, _OPTIONS, args.typed)) from None
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def run_study_command(args) -> int:
    config = _config(args)
    params = parse_params(args.param)

    from eha_core.cancel import CancelToken
    from eha_core.study import run_study

    token = CancelToken()
    res = _with_progress(lambda progress: run_study(config, params, workers=args.workers, progress=progress,
                                                    cancel=token), config.n_seeds, args.json, token)
    if args.json:
        print(json_text(res.to_dict()))
    else:
        print(summary_text(res))
    if res.n_failed:
        print(f"eha study {config.kind}: warning: {res.message}", file=sys.stderr)
    return 0 if res.n_failed == 0 else 1


def _greybox_config(args):
    """The checked :class:`~eha_core.identify.greybox_study.GreyBoxStudyConfig`."""
    from eha_core.identify.greybox import GREYBOX_PARAMS, GREYBOX_SIGNALS
    from eha_core.identify.greybox_study import GreyBoxStudyConfig
    from eha_core.study import MAX_SEEDS, MAX_WORKERS

    check_range("--seeds", args.seeds, 1, MAX_SEEDS, "seeds")
    check_range("--workers", args.workers, 1, MAX_WORKERS, "threads")
    check_range("--first-seed", args.first_seed, 0, 2**32 - 1 - MAX_SEEDS)

    def names(option, text, allowed):
        got = tuple(n.strip() for n in str(text).split(",") if n.strip())
        for n in got:
            if n not in allowed:
                raise refused(option, text, f"{n} is not one of {', '.join(allowed)}", value_text=text)
        if not got or len(set(got)) != len(got):
            raise refused(option, text, f"name each of {', '.join(allowed)} at most once, at least one",
                          value_text=text)
        return got

    try:
        return GreyBoxStudyConfig(n_seeds=args.seeds, first_seed=args.first_seed,
                                  params=names("--params", args.params, GREYBOX_PARAMS),
                                  measured=names("--measured", args.measured, GREYBOX_SIGNALS),
                                  snr_db=args.snr_db, t_end=args.t_end, truth=parse_params(args.param))
    except FieldError as exc:
        raise UsageError(as_typed(exc, {"snr_db": "--snr-db", "t_end": "--t-end"}, args.typed)) from None


def run_greybox_study_command(args) -> int:
    config = _greybox_config(args)
    from eha_core.cancel import CancelToken
    from eha_core.identify.greybox_study import run_greybox_study

    token = CancelToken()
    res = _with_progress(lambda progress: run_greybox_study(config, workers=args.workers, progress=progress,
                                                            cancel=token), config.n_seeds, args.json, token)
    print(json_text(res.to_dict()) if args.json else greybox_summary_text(res))
    if res.n_failed:
        print(f"eha study greybox: warning: {res.n_failed} seeds failed: {'; '.join(res.failures[:3])}",
              file=sys.stderr)
    return 0 if res.n_failed == 0 else 1


def greybox_summary_text(res) -> str:
    """The grey-box study as a table: per parameter truth, mean, std, bias/se, coverage, CRB, std/CRB."""
    from eha_core.study import coverage_band

    cfg = res.config
    noise = ", ".join(f"{k} {v:.3g}" for k, v in res.noise.items())
    lines = [f"study: grey-box estimate of {', '.join(cfg.params)} from {', '.join(cfg.measured)}, "
             f"{cfg.t_end:g} s, noise at {cfg.snr_db:g} dB ({noise}, SI)",
             f"seeds {cfg.first_seed}-{cfg.first_seed + cfg.n_seeds - 1}: {res.n_completed} completed, "
             f"{res.n_failed} failed, {res.elapsed_s:.1f} s ({res.seconds_per_seed:.2f} s per seed)"]

    def num(v, fmt=".5g"):
        return "-" if v is None or not math.isfinite(v) else format(v, fmt)

    rows = [[k, num(res.truth[k]), num(res.mean[k]), num(res.std[k], ".4g"), num(res.mean_std_error[k], ".4g"),
             num(res.bias_se[k], "+.3f"), num(res.coverage[k], ".3f"), num(res.crb[k], ".4g"),
             num(res.std_over_crb[k], ".3f"), f"held in {res.held[k]}" if res.held[k] else ""] for k in cfg.params]
    lines += table_text(["parameter", "truth", "mean", "std", "mean se", "bias/se", "coverage", "CRB", "std/CRB", ""],
                        rows, align="lrrrrrrrrl")
    if res.n_completed:
        lo, hi = coverage_band(res.n_completed)
        lines.append(f"coverage: the fraction of seeds whose 95 % interval holds the truth; honest intervals give "
                     f"{lo:.3f}-{hi:.3f} in 99 % of studies of {res.n_completed} seeds")
        lines.append("CRB: the Cramer-Rao bound, the smallest std an unbiased estimator can have here; std/CRB near 1: "
                     "the estimator uses the data's information")
    if res.n_failed:
        lines.append(f"failed: {res.n_failed} seeds whose estimate failed its own checks (residuals, noise, bounds, "
                     "rank) or could not be computed; they are not in the statistics")
    if res.without_hold is not None:
        w = res.without_hold
        cover = ", ".join(f"{k} {num(w['coverage'].get(k), 0, '.3f')}" for k in cfg.params)
        lines.append(f"without holding (every parameter estimated, the same seeds): coverage {cover} "
                     f"({w['n_completed']} completed, {w['n_failed']} failed)")
    return "\n".join(lines)


def _bias_text(res, name: str) -> str:
    """``+0.012 +- 0.032`` (the bias in mean standard errors, +- its Monte Carlo error), ``!`` when the seeds
    show a bias; ``-`` without the data for it."""
    bias, mc, se = (d.get(name, math.nan) for d in (res.bias_per_std_error, res.bias_std_error,
                                                   res.mean_std_error))
    if not math.isfinite(bias):
        return "- "
    if not math.isfinite(mc):
        return f"{bias:+.3f} "
    return f"{bias:+.3f} +- {mc / se:.3f}{'!' if res.biased(name) else ' '}"


def _with_progress(run, total: int, quiet: bool, token):
    """``run(progress)`` with a progress line on a terminal (none with ``quiet``: JSON goes to stdout), Ctrl-C
    setting ``token``."""
    progress = _Progress(total) if sys.stderr.isatty() and not quiet else None
    try:
        with interrupt_cancels(token):
            return run(progress)
    finally:
        if progress is not None:
            progress.close()


class _Progress:
    """A progress line on stderr (a terminal only), rewritten in place."""

    def __init__(self, total: int):
        self.total, self.shown = total, False

    def __call__(self, done: int, total: int) -> None:
        print(f"\reha study: {done}/{total} seeds", end="", file=sys.stderr, flush=True)
        self.shown = True

    def close(self) -> None:
        if self.shown:
            print(file=sys.stderr)


def summary_text(res) -> str:
    """The study as a table: parameter, nominal, mean, std, mean reported std error, bias in those, coverage."""
    from eha_core.identify.lse_choices import DEFAULT_INTERVALS

    cfg = res.config
    last = cfg.first_seed + cfg.n_seeds - 1
    if cfg.kind == "lse":
        method = "instrumental variables" if cfg.estimator == "iv" else "least squares"
        if cfg.intervals != DEFAULT_INTERVALS[cfg.estimator]:
            method += f" with {cfg.intervals} intervals"
        what = (f"{method}, disturbance {cfg.disturbance}, disturbance model {cfg.disturbance_model}"
                + (f", sensor noise {', '.join(f'{k}={v:g}' for k, v in cfg.sensor_noise)}" if cfg.sensor_noise
                   else ""))
    else:
        what = (f"transfer function H(s) = b0 / (s^3 + a1 s^2 + a2 s + a3), {cfg.model} plant, "
                f"position noise {cfg.noise_m:g} m")
    lines = [f"study: {what}",
             f"seeds {cfg.first_seed}-{last}: {res.n_completed} completed, {res.n_failed} failed, "
             f"{res.workers} workers, {res.elapsed_s:.2f} s ({res.seconds_per_seed:.4f} s per seed)",
             f"nominal: {res.reference}"]

    def num(v, fmt=".6g"):
        return "-" if v is None or not math.isfinite(v) else format(v, fmt)

    # every column as wide as its widest cell: a wide number (a bias of -3728 standard errors) does not
    # run into its neighbour
    rows = [[k, num(res.nominal.get(k)), num(res.mean[k]), num(res.std[k], ".4g"), num(res.mean_std_error[k], ".4g"),
             _bias_text(res, k), num(res.coverage.get(k), ".3f")] for k in res.parameters]
    lines += table_text(["parameter", "nominal", "mean", "std", "mean std err", "bias/se", "coverage"], rows)
    if res.n_successful:
        lo, hi = res.coverage_band()
        lines.append("bias/se: (mean - nominal) / mean std err, +- its Monte Carlo error (std / sqrt(seeds)) in the "
                     "same unit; ! the seeds show a bias (beyond 2.58 of those, 99 %)")
        lines.append(f"coverage: the fraction of seeds whose 95 % interval holds the nominal value; honest intervals "
                     f"give {lo:.3f}-{hi:.3f} in 99 % of studies of {res.n_successful} seeds")
    if res.message != "ok":
        lines.append(f"note: {res.message}")
    return "\n".join(lines)
