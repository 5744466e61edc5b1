"""``eha idinput``: an excitation signal compatible with MATLAB's idinput."""

from __future__ import annotations

import sys

from .common import check_output_file, check_range, json_text, refused, refused_file

#: Samples of one signal at most (80 MB of floats).
MAX_SAMPLES = 10_000_000
#: 'sine' draws NT trials of N samples each: their product is bounded (memory).
MAX_SINE_TRIAL_SAMPLES = 20_000_000


def add_parser(sub) -> None:
    ii = sub.add_parser("idinput", help="excitation signal compatible with MATLAB's idinput",
                        description="Excitation compatible with MATLAB's idinput: conventions in eha_core.excitation.")
    ii.add_argument("--type", default="rgs", help="rgs (default), rbs, prbs or sine")
    ii.add_argument("--n", type=int, required=True, help=f"number of samples (one period), 1 to {MAX_SAMPLES}")
    ii.add_argument("--band", type=float, nargs=2, default=(0.0, 1.0), metavar=("LO", "HI"),
                    help="pass band in fractions of the Nyquist frequency (default 0 1); prbs: [0 B], clock period 1/B")
    ii.add_argument("--range", type=float, nargs=2, default=(-1.0, 1.0), metavar=("MIN", "MAX"),
                    help="levels (rbs, prbs), mean -/+ one std (rgs), or the span (sine); default -1 1")
    ii.add_argument("--sinedata", type=int, nargs=3, default=(10, 10, 1), metavar=("NS", "NT", "GS"),
                    help="sine: number of sinusoids (1-5000), trials (1-500), grid skip (1-100); default 10 10 1")
    ii.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    ii.add_argument("--out", help="write the CSV (columns k,u) to this file")
    ii.add_argument("--json", action="store_true", help='print {"u": [...], "freqs": [...]} (freqs in rad/sample)')
    ii.set_defaults(handler=run, fields={"type": "--type", "n": "--n", "band": "--band", "range": "--range",
                                         "sinedata": "--sinedata", "seed": "--seed"})


def run(args) -> int:
    check_range("--n", args.n, 1, MAX_SAMPLES, "samples")
    ns, nt, gs = args.sinedata
    check_range("--sinedata NS", ns, 1, 5000, "sinusoids")
    check_range("--sinedata NT", nt, 1, 500, "trials")
    check_range("--sinedata GS", gs, 1, 100)
    if args.type == "sine" and nt * args.n > MAX_SINE_TRIAL_SAMPLES:
        raise refused("--sinedata NT", nt, f"trials x samples must be at most {MAX_SINE_TRIAL_SAMPLES} (each trial "
                      "is a whole signal in memory); use fewer trials", context=f"with --n {args.n}")
    if args.seed < 0:
        raise refused("--seed", args.seed, "use a whole number >= 0")
    check_output_file("--out", args.out)
    from eha_core.excitation import idinput

    ex = idinput(args.n, args.type, tuple(args.band), tuple(args.range), tuple(args.sinedata), seed=args.seed)
    if args.json:
        print(json_text({"u": ex.u, "freqs": ex.freqs.ravel()}))
        return 0
    table = ex.to_pandas()
    if args.out:
        try:
            table.to_csv(args.out, index=False, float_format="%.10g")
        except OSError as exc:
            raise refused_file("--out", args.out, f"{exc.strerror or exc}") from None
    else:
        table.to_csv(sys.stdout, index=False, float_format="%.10g")
    return 0
