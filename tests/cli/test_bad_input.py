"""Every subcommand refuses a bad input with one line naming the option as typed, and exit code 2.

A newcomer types a negative number, a word where a number goes, NaN, a huge value, a folder or a
binary file where a file goes: the command ends with ``eha: error: OPTION = VALUE is not allowed:
WHAT`` on stderr and nothing else (no traceback, no numpy warning), and exit code 2. A computation
the inputs do not allow (a simulation that diverges) is refused the same way, naming the typed value
it follows from.
"""

from __future__ import annotations

import pytest

from eha_app.cli import main

#: (argv, the line's start: the option as typed and its value as typed). Paths are filled in by
#: ``files``: {dir} a folder, {bin} a binary file, {empty} an empty one, {missing} none, {new} a file
#: name free to write, {exercise} an exercise file, {renamed} a record whose columns have other names
#: (time, position[mm], ...), {odd} one whose columns cannot be guessed (a, b, c), {roster} an exercise file
#: with a roster (s1) and a deadline.
CASES = [
    # simulate
    (["simulate", "--case", "7"], "--case = 7"),
    (["simulate", "--case", "x"], "--case = x"),
    (["simulate", "--case", "1", "--t-end", "-3"], "--t-end = -3"),
    (["simulate", "--case", "1", "--t-end", "nan"], "--t-end = nan"),
    (["simulate", "--case", "1", "--t-end", "1e9"], "--t-end = 1e9"),
    (["simulate", "--case", "1", "--dt", "0.003"], "--dt = 0.003"),
    (["simulate", "--case", "1", "--dt", "0"], "--dt = 0"),
    (["simulate", "--case", "1", "--param", "M=-1"], "--param M = -1"),
    (["simulate", "--case", "1", "--param", "M=abc"], "--param M = abc"),
    (["simulate", "--u", "sine:nan:2"], "--u = sine:nan:2"),
    (["simulate", "--case", "1", "--out", "{dir}"], "--out = '{dir}'"),
    # linearize: an overflow is refused by name, without numpy's warnings
    (["linearize", "--kp", "1e308"], "--kp = 1e308"),
    (["linearize", "--kp", "-1"], "--kp = -1"),
    (["linearize", "--kp", "ten"], "--kp = ten"),
    (["linearize", "--param", "M=1e-320"], "--param M = 1e-320"),
    (["linearize", "--param", "M=nan"], "--param M = nan"),
    (["linearize", "--param", "M"], "--param = M"),
    # idinput
    (["idinput", "--n", "0"], "--n = 0"),
    (["idinput", "--n", "ten"], "--n = ten"),
    (["idinput", "--n", "10", "--type", "pink"], "--type = pink"),
    (["idinput", "--n", "10", "--band", "nan", "1"], "--band = nan 1"),
    (["idinput", "--n", "10", "--range", "1", "-1"], "--range = 1 -1"),
    (["idinput", "--n", "10", "--out", "{dir}"], "--out = '{dir}'"),
    # identify lse
    (["identify", "lse", "--t-end", "0.2", "--tau-f", "1e6"], "--tau-f = 1e6"),
    (["identify", "lse", "--tau-f", "-1"], "--tau-f = -1"),
    (["identify", "lse", "--t-end", "0.001"], "--t-end = 0.001"),
    (["identify", "lse", "--seed", "x"], "--seed = x"),
    (["identify", "lse", "--data", "{missing}"], "--data = '{missing}'"),
    (["identify", "lse", "--data", "{dir}"], "--data = '{dir}'"),
    (["identify", "lse", "--data", "{bin}"], "--data = '{bin}'"),
    (["identify", "lse", "--data", "{empty}"], "--data = '{empty}'"),
    (["identify", "lse", "--t-end", "0.2", "--u", "sine:1e308:2"], "--u = sine:1e308:2"),
    (["identify", "lse", "--t-end", "0.2", "--param", "beta_e=1e300"], "--param beta_e = 1e300"),
    (["identify", "lse", "--data", "{renamed}", "--columns", "q=time"], "--columns = q=time"),
    (["identify", "lse", "--data", "{renamed}", "--columns", "x=pos"], "--columns = x=pos"),
    (["identify", "lse", "--data", "{renamed}", "--columns", "x"], "--columns = x"),
    (["identify", "lse", "--columns", "t=time"], "--columns = t=time"),
    (["identify", "lse", "--data", "{odd}"], "--data = '{odd}'"),
    # identify tf: the closed-loop simulation that diverges names the gain typed
    (["identify", "tf", "--kp", "1e308"], "--kp = 1e308"),
    (["identify", "tf", "--kp", "nan"], "--kp = nan"),
    (["identify", "tf", "--ts", "0"], "--ts = 0"),
    (["identify", "tf", "--ts", "1e9"], "--ts = 1e9"),
    (["identify", "tf", "--np", "0"], "--np = 0"),
    (["identify", "tf", "--data", "{empty}"], "--data = '{empty}'"),
    (["identify", "tf", "--data", "{renamed}", "--columns", "y=nothere"], "--columns = y=nothere"),
    (["identify", "tf", "--data", "{odd}"], "--data = '{odd}'"),
    # identify greybox
    (["identify", "greybox", "--noise", "x=-1mm"], "--noise = x=-1mm"),
    (["identify", "greybox", "--t-end", "nan"], "--t-end = nan"),
    (["identify", "greybox", "--shooting", "x"], "--shooting = x"),
    (["identify", "greybox", "--data", "{bin}"], "--data = '{bin}'"),
    (["identify", "greybox", "--data", "{renamed}", "--measured", "x", "--columns", "v=velocity"],
     "--columns = v=velocity"),
    (["identify", "greybox", "--data", "{odd}"], "--data = '{odd}'"),
    (["identify", "greybox", "--t-end", "0.5", "--u", "sine:1e308:2"], "--u = sine:1e308:2"),
    # identify: the black-box structures (orders the record cannot support, a delay past the record, a
    # merged experiment with another sample time)
    (["identify", "arx", "--na", "-1"], "--na = -1"),
    (["identify", "armax", "--nc", "x"], "--nc = x"),
    (["identify", "oe", "--nf", "99"], "--nf = 99"),
    (["identify", "bj", "--nk", "-1"], "--nk = -1"),
    (["identify", "arx", "--samples", "100", "--na", "40", "--nb", "40"], "--na = 40"),
    (["identify", "arx", "--samples", "100", "--nk", "500"], "--nk = 500"),
    (["identify", "ss", "--n", "0"], "--n = 0"),
    (["identify", "oe", "--experiments", "9"], "--experiments = 9"),
    (["identify", "oe", "--experiments", "2", "--validation", "split"], "--validation = split"),
    (["identify", "process", "--kind", "P3"], "--kind = P3"),
    (["identify", "process", "--input-offset", "guess"], "--input-offset = guess"),
    (["identify", "select", "--structure", "fir"], "--structure = fir"),
    (["identify", "arx", "--data", "{bin}"], "--data = '{bin}'"),
    # study
    (["study", "lse", "--seeds", "0"], "--seeds = 0"),
    (["study", "lse", "--seeds", "x"], "--seeds = x"),
    (["study", "lse", "--seeds", "2", "--noise", "x=-1"], "--noise = x=-1"),
    (["study", "lse", "--seeds", "2", "--t-end", "0.001"], "--t-end = 0.001"),
    (["study", "tf", "--seeds", "2", "--noise", "nan"], "--noise = nan"),
    (["study", "greybox", "--seeds", "2", "--snr-db", "-1e9"], "--snr-db = -1e9"),
    (["study", "greybox", "--seeds", "2", "--t-end", "-1"], "--t-end = -1"),
    # reproduce
    (["reproduce", "--seed", "-1"], "--seed = -1"),
    (["reproduce", "--out", "{bin}"], "--out = '{bin}'"),
    # serve: refused before anything starts
    (["serve", "--address", "notanaddress.invalid"], "--address = notanaddress.invalid"),
    (["serve", "--port", "abc"], "--port = abc"),
    (["serve", "--port", "0"], "--port = 0"),
    (["serve", "--exercise", "{bin}"], "--exercise = '{bin}'"),
    (["serve", "--exercise", "{empty}"], "--exercise = '{empty}'"),
    (["serve", "--exercise", "{missing}"], "--exercise = '{missing}'"),
    # exercise
    (["exercise", "new", "--feedback", "after-deadline", "--out", "{new}"], "--feedback = after-deadline"),
    (["exercise", "new", "--deadline", "2020-01-01T00:00", "--out", "{new}"], "--deadline = 2020-01-01T00:00"),
    (["exercise", "new", "--vary", "-5%", "--out", "{new}"], "--vary = "),
    (["exercise", "new", "--attempt-penalty", "150%", "--out", "{new}"], "--attempt-penalty = 150%"),
    (["exercise", "new", "--attempt-penalty", "lots", "--out", "{new}"], "--attempt-penalty = lots"),
    (["exercise", "new", "--k", "0.5", "--out", "{new}"], "--k = 0.5 is not allowed: a number of standard errors"),
    (["exercise", "new", "--variants", "paper,leak", "--out", "{new}"],
     "--variants = leak is not allowed: not a variant"),
    (["exercise", "new", "--variants", ",", "--out", "{new}"], "--variants = (none) is not allowed: name at least one"),
    (["exercise", "new", "--k", "three", "--out", "{new}"], "--k = three"),
    (["exercise", "new", "--floor", "60%", "--out", "{new}"], "--floor = 60 %"),
    (["exercise", "new", "--tolerance", "Q=5%", "--out", "{new}"], "--tolerance = Q=5%"),
    (["study", "grading", "--route", "arx"], "--route = arx"),
    (["study", "grading", "--students", "1"], "--students = 1"),
    (["study", "grading", "--experiment", "best"], "--experiment = best"),
    (["exercise", "new", "--noise", "x=-1mm", "--out", "{new}"], "--noise = x=-1mm"),
    (["exercise", "new", "--roster", "{bin}", "--out", "{new}"], "--roster = '{bin}'"),
    (["exercise", "new", "--out", "{dir}"], "--out = '{dir}'"),
    (["exercise", "results", "{bin}"], "exercise = '{bin}'"),
    (["exercise", "results", "{empty}"], "exercise = '{empty}'"),
    (["exercise", "reveal", "{bin}", "--student", "ada"], "exercise = '{bin}'"),
    (["exercise", "token", "{exercise}", "--days", "-1"], "--days = -1"),
    (["exercise", "new", "--deadline", "2099-01-02T00:00", "--release-truth-at", "2099-01-01T00:00", "--out", "{new}"],
     "--release-truth-at = 2099-01-01T00:00"),
    (["exercise", "new", "--release-truth-at", "soon", "--out", "{new}"], "--release-truth-at = soon"),
    (["exercise", "new", "--release-truth-at", "2020-01-01T00:00", "--out", "{new}"],
     "--release-truth-at = 2020-01-01T00:00"),
    (["exercise", "results", "{exercise}", "--format", "moodle", "--out", "{new}", "--points", "0"], "--points = 0"),
    (["exercise", "results", "{exercise}", "--format", "canvas"], "--format = canvas"),
    (["exercise", "extend", "{roster}", "--student", "s9", "--until", "2099-02-01T00:00"], "--student = s9"),
    (["exercise", "extend", "{roster}", "--student", "s1", "--until", "next friday"], "--until = next friday"),
    (["exercise", "extend", "{roster}", "--student", "s1", "--until", "2098-12-31T00:00"],
     "--until = 2098-12-31T00:00"),
    (["exercise", "extend", "{exercise}", "--student", "ada", "--until", "2099-02-01T00:00"],
     "--until = 2099-02-01T00:00"),
    (["exercise", "extend", "{bin}", "--student", "s1", "--until", "2099-02-01T00:00"], "exercise = '{bin}'"),
]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    from eha_core.exercise import Exercise

    root = tmp_path_factory.mktemp("bad")
    (root / "folder").mkdir()
    (root / "binary.json").write_bytes(b"\x80\x81\x00 not text")
    (root / "empty.csv").write_text("")
    Exercise.new(hide=("M",)).save(root / "class.json")
    Exercise.new(hide=("M",), roster=[("s1", "Ada")], deadline="2099-01-01T00:00").save(root / "roster.json")
    (root / "renamed.csv").write_text("time,position[mm],velocity[mm/s],pA[bar],pB[bar],valve[V]\n"
                                      + "".join(f"{k * 1e-3},0,0,120,180,0\n" for k in range(60)))
    (root / "odd.csv").write_text("a,b,c\n" + "".join(f"{k},0,0\n" for k in range(60)))
    return {"dir": str(root / "folder"), "bin": str(root / "binary.json"), "empty": str(root / "empty.csv"),
            "missing": str(root / "nothere.csv"), "new": str(root / "new.json"), "exercise": str(root / "class.json"),
            "renamed": str(root / "renamed.csv"), "odd": str(root / "odd.csv"), "roster": str(root / "roster.json")}


@pytest.mark.parametrize("argv, named", CASES, ids=[" ".join(argv) for argv, _ in CASES])
def test_a_bad_input_is_one_line_naming_the_option_as_typed(capsys, files, argv, named):
    code = main([word.format(**files) for word in argv])
    out, err = capsys.readouterr()
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2, err
    assert len(lines) == 1 and err.endswith("\n"), err
    assert "Traceback" not in out + err
    assert lines[0].startswith(f"eha: error: {named.format(**files)}"), lines[0]
    assert " is not allowed" in lines[0]


def test_every_subcommand_has_bad_inputs_in_the_table():
    from eha_app.cli import build_parser

    parser = build_parser()
    (sub,) = [a for a in parser._actions if a.dest == "command"]
    tried = {argv[0] for argv, _ in CASES}
    assert set(sub.choices) <= tried
    for command in ("identify", "study"):
        (methods,) = [a for a in sub.choices[command]._actions if a.dest == "method"]
        assert set(methods.choices) <= {argv[1] for argv, _ in CASES if argv[0] == command}, command


def test_a_refused_overflow_prints_no_numpy_warning(capsys):
    assert main(["linearize", "--kp", "1e308"]) == 2
    err = capsys.readouterr().err
    assert "overflow" not in err and "note" not in err and "infs or NaNs" not in err


def test_a_computation_that_fails_names_each_value_typed_that_feeds_it(capsys):
    assert main(["identify", "tf", "--kp", "1e308", "--param", "M=3000", "--seed", "2"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("eha: error: --kp = 1e308 is not allowed with --param M=3000: the closed-loop simulation "
                          "failed: ")
    assert "--seed" not in err                          # the excitation's seed does not make a loop diverge


def test_a_rule_broken_by_a_value_not_typed_says_which_assignment_it_follows_from(capsys):
    assert main(["linearize", "--param", "Dc=0.01"]) == 2
    assert capsys.readouterr().err == ("eha: error: dc = 0.07 is not allowed with --param Dc=0.01: the rod diameter "
                                       "must be smaller than the bore Dc = 0.01 m\n")


def test_the_tau_f_refusal_says_the_longest_allowed_and_that_one_is_taken(capsys):
    assert main(["identify", "lse", "--t-end", "0.2", "--tau-f", "1"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("eha: error: --tau-f = 1 is not allowed: the first 5 tau_f ")
    # 201 samples at 1 kHz: 20 are left while 5 tau_f <= 0.181 s (0.0362 itself leaves 19, in floats)
    assert err.rstrip().endswith("use at most 0.03619 s")
    assert main(["identify", "lse", "--t-end", "0.2", "--tau-f", "0.03619", "--json"]) != 2
    capsys.readouterr()


def test_an_address_another_machine_has_names_the_address_not_the_port():
    from eha_app.cli.common import UsageError
    from eha_app.cli.serve import check_port_free

    with pytest.raises(UsageError) as refusal:
        check_port_free("192.0.2.1", 5006)          # TEST-NET-1: no machine's own address
    assert refusal.value.error.field == "--address"


@pytest.mark.parametrize("argv, says", [
    (["identify"], "identify needs a METHOD: lse, tf or greybox"),
    (["study"], "study needs a METHOD: lse, tf, greybox or grading"),
    (["exercise"], "exercise needs an ACTION: new, codes, results, reveal, extend, token or copy-store"),
    (["frobnicate"], "argument COMMAND: invalid choice: 'frobnicate'"),
])
def test_a_missing_or_unknown_subcommand_is_one_line(capsys, argv, says):
    code = main(argv)
    out, err = capsys.readouterr()
    assert code == 2 and out == "" and err.startswith(f"eha: error: {says}") and err.count("\n") == 1, err
