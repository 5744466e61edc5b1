"""The deployment guide's files (docs/deployment.md, deploy/): the systemd unit's command is one that
``eha serve`` takes, the unit has what systemd needs, nginx accepts the site file and it is what
``eha serve --nginx-config`` prints but for its upstream, and every ``eha`` command in the guide names
subcommands and options that exist (the whole command parses, where it is a command to run)."""

from __future__ import annotations

import argparse
import configparser
import re
import shlex
import shutil
import subprocess
from pathlib import Path

import pytest

from eha_app.cli import build_parser, main
from eha_app.cli.common import UsageError
from eha_app.runtime.store_backend import PostgresBackend, is_postgres_url, shown_url
from tests.serve.conftest import free_port

ROOT = Path(__file__).resolve().parents[2]
GUIDE = ROOT / "docs" / "deployment.md"
UNIT = ROOT / "deploy" / "systemd" / "eha-serve@.service"
ENV_FILE = ROOT / "deploy" / "systemd" / "eha.env"
SITE = ROOT / "deploy" / "nginx" / "eha.conf"

#: The names the guide, the unit and the site file agree on.
COURSE_HOST = "lab.example.edu"
BACKENDS = ["host-a:8081", "host-b:8081"]
#: The words of a shell line that end an ``eha`` command.
SHELL_OPERATORS = {"&&", "||", "|", ";", "&", ">", ">>", "2>&1", ")"}
#: eha's subcommands (a word "eha" followed by another is the user's name: sudo -u eha, createdb --owner eha)
SUBCOMMANDS = {"simulate", "linearize", "idinput", "identify", "reproduce", "serve", "exercise", "study"}


# -- helpers -------------------------------------------------------------------------------------------
def _unit() -> configparser.ConfigParser:
    unit = configparser.ConfigParser(strict=False, interpolation=None, delimiters=("=",))
    unit.optionxform = str                      # systemd's keys are case-sensitive
    unit.read_string(UNIT.read_text(encoding="utf-8"))
    return unit


def _unit_lines(key: str) -> list[str]:
    """Every ``key=`` line of the unit (configparser keeps only the last of a repeated key)."""
    return [line.split("=", 1)[1].strip() for line in UNIT.read_text(encoding="utf-8").splitlines()
            if line.startswith(key + "=")]


def _exec_start_argv(port: int = 8081) -> list[str]:
    return shlex.split(_unit()["Service"]["ExecStart"].replace("%i", str(port)))


def _parse(argv: list[str]) -> argparse.Namespace:
    """``eha ARGV`` as eha's own parser reads it (UsageError, not SystemExit, on a refusal)."""
    return build_parser().parse_args(argv)


def _subcommand(words: list[str]) -> tuple[argparse.ArgumentParser, list[str], list[str]]:
    """The parser of the (sub)subcommand ``words`` start with, the words naming it, and the rest."""
    parser, named = build_parser(), []
    rest = list(words)
    while rest:
        subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        if not subs or rest[0] not in subs[0].choices:
            break
        parser = subs[0].choices[rest[0]]
        named.append(rest.pop(0))
    return parser, named, rest


def _code_blocks(text: str) -> list[str]:
    return re.findall(r"^\s*```[^\n]*\n(.*?)^\s*```", text, flags=re.M | re.S)


def _eha_commands(block: str) -> list[list[str]]:
    """The ``eha ...`` commands of a shell block: continuation lines joined, comments dropped, each
    command's words up to the first shell operator."""
    commands = []
    for line in re.sub(r"\\\n\s*", " ", block).splitlines():
        try:
            words = shlex.split(line, comments=True)
        except ValueError:
            continue
        for k, word in enumerate(words):
            if Path(word).name == "eha" and k + 1 < len(words) and words[k + 1] in SUBCOMMANDS:
                command = []
                for w in words[k + 1:]:
                    if w in SHELL_OPERATORS:
                        break
                    command.append(w)
                commands.append(command)
                break
    return commands


def _flat(text: str) -> str:
    return " ".join(text.split())


# -- the systemd unit ----------------------------------------------------------------------------------
def test_the_units_command_is_one_eha_serve_takes():
    argv = _exec_start_argv(8081)
    assert argv[0].startswith("/") and Path(argv[0]).name == "eha", "systemd needs the absolute path of eha"
    args = _parse(argv[1:])
    assert args.command == "serve"
    assert args.exercise == "/var/lib/eha/class.json"
    assert args.port == 8081 and args.address == "0.0.0.0" and args.behind_proxy
    assert args.workers is not None and args.workers >= 1
    # the bare course name: a browser sends no port for http:80 and https:443, and the server counts a name
    # without a port as port 80 (a NAME:443 entry would refuse every page behind HTTPS)
    assert args.allow_websocket_origin == [COURSE_HOST]
    assert args.num_procs == 1, "one process per instance: the processes of --num-procs share one spool file"
    # eha serve's own checks of the values (the port's range, the workers', the address)
    from eha_app.cli.serve import _validate

    _validate(args)


def test_the_unit_refuses_a_typo_in_its_command():
    """The check above can fail: an option eha serve does not have is refused by the same parser."""
    argv = _exec_start_argv(8081)
    with pytest.raises(UsageError):
        _parse(argv[1:] + ["--behind-proxie"])
    with pytest.raises(UsageError):
        _parse([w.replace("--port", "--prot") for w in argv[1:]])


def test_the_unit_has_what_systemd_and_the_guide_need():
    unit = _unit()
    assert {"Unit", "Service", "Install"} <= set(unit.sections())
    for key in ("Description", "After", "Wants"):
        assert unit["Unit"].get(key), f"[Unit] {key}="
    assert "network-online.target" in unit["Unit"]["After"]
    service = unit["Service"]
    for key in ("Type", "User", "Group", "WorkingDirectory", "EnvironmentFile", "ExecStart", "Restart", "RestartSec"):
        assert service.get(key), f"[Service] {key}="
    assert service["WorkingDirectory"] == "/var/lib/eha"
    assert service["EnvironmentFile"] == "/etc/eha/eha.env"
    assert service["User"] != "root"
    assert service["Restart"] in ("on-failure", "always")
    assert unit["Install"].get("WantedBy") == "multi-user.target"
    # the spool of waiting hand-ins: one per instance (two instances sharing one file would lose lines)
    spools = [v for v in _unit_lines("Environment") if v.startswith("EHA_SPOOL=")]
    assert len(spools) == 1 and "%i" in spools[0] and spools[0].split("=", 1)[1].startswith("/var/lib/eha/")
    # the password is in ~/.pgpass, never in the unit (systemctl show prints the unit to every user)
    assert "EHA_STORE" not in "".join(_unit_lines("Environment"))
    assert "%i" in service["ExecStart"] and "--store" not in service["ExecStart"]


def test_systemd_reads_the_unit(tmp_path):
    analyze = shutil.which("systemd-analyze")
    if analyze is None:
        pytest.skip("systemd-analyze is not installed")
    unit = tmp_path / "eha-serve@8081.service"
    unit.write_text(UNIT.read_text(encoding="utf-8"), encoding="utf-8")
    out = subprocess.run([analyze, "verify", str(unit)], capture_output=True, text=True, timeout=60)
    said = (out.stdout + out.stderr).splitlines()
    # (on a machine without eha in /opt/eha and without the eha user, systemd says so: not the unit's fault)
    wrong = [line for line in said if re.search(r"unknown (key|section|lvalue)|failed to parse|invalid|"
                                                r"ignoring|bad (unit|setting)|missing '='", line, re.I)]
    assert not wrong, "\n".join(said)


def test_the_environment_file_gives_the_store_without_a_password(monkeypatch):
    values = dict(line.split("=", 1) for line in ENV_FILE.read_text(encoding="utf-8").splitlines()
                  if line.strip() and not line.lstrip().startswith("#"))
    assert set(values) == {"EHA_STORE"}
    url = values["EHA_STORE"]
    assert is_postgres_url(url) and shown_url(url) == url, "the password goes in ~/.pgpass, not here"
    assert url.split("@", 1)[1].split("/", 1)[0].count(":") == 1, "USER@HOST:PORT"
    # systemd puts it in the environment, where eha serve's --store finds it (no --store in the unit)
    monkeypatch.setenv("EHA_STORE", url)
    assert _parse(_exec_start_argv()[1:]).store == url
    assert url in GUIDE.read_text(encoding="utf-8")


# -- nginx -------------------------------------------------------------------------------------------
def _site_backends(text: str) -> list[str]:
    return re.findall(r"^\s*server\s+(\S+)\s+max_fails=1 fail_timeout=10s;", text, flags=re.M)


def _config_lines(text: str) -> list[str]:
    return [line.rstrip() for line in text.splitlines() if line.strip() and not line.lstrip().startswith("#")]


def test_the_site_file_is_what_eha_serve_prints_but_for_its_upstream(capsys):
    site = SITE.read_text(encoding="utf-8")
    assert _site_backends(site) == BACKENDS
    assert main(["serve", "--nginx-config", "2", "--port", "80"]) == 0
    printed = capsys.readouterr().out
    printed = printed.replace("server 127.0.0.1:81 ", f"server {BACKENDS[0]} ") \
                     .replace("server 127.0.0.1:82 ", f"server {BACKENDS[1]} ")
    assert _config_lines(site) == _config_lines(printed)
    # the instances of the guide are the upstream's ports
    guide = GUIDE.read_text(encoding="utf-8")
    assert {b.rsplit(":", 1)[1] for b in BACKENDS} == {"8081"} and "eha-serve@8081" in guide
    assert str(_parse(_exec_start_argv(8081)[1:]).port) == "8081"


def _nginx() -> str | None:
    found = shutil.which("nginx")
    if found is None and Path("/usr/sbin/nginx").is_file():
        found = "/usr/sbin/nginx"
    return found


def test_nginx_accepts_the_site_file(tmp_path):
    nginx = _nginx()
    if nginx is None:
        pytest.skip("nginx is not installed")
    site = SITE.read_text(encoding="utf-8")
    backends = _site_backends(site)
    assert backends == BACKENDS
    # host-a and host-b resolve on the course's nginx only: here, ports of this machine
    for backend in backends:
        site = site.replace(f"server {backend} ", f"server 127.0.0.1:{free_port()} ")
    site, listens = re.subn(r"^(\s*listen\s+)80;", rf"\g<1>127.0.0.1:{free_port()};", site, flags=re.M)
    assert listens == 1
    (tmp_path / "eha.conf").write_text(site, encoding="utf-8")
    temp = "\n".join(f"    {kind}_temp_path {tmp_path}/{kind};" for kind in
                     ("client_body", "proxy", "fastcgi", "uwsgi", "scgi"))
    conf = tmp_path / "nginx.conf"
    conf.write_text(f"""worker_processes 1;
pid {tmp_path}/nginx.pid;
error_log {tmp_path}/error.log warn;
events {{ worker_connections 64; }}
http {{
    access_log {tmp_path}/access.log;
{temp}
    include {tmp_path}/eha.conf;
}}
""", encoding="utf-8")
    usage = subprocess.run([nginx, "-h"], capture_output=True, text=True, timeout=30)
    early_log = ["-e", str(tmp_path / "error.log")] if "-e filename" in usage.stdout + usage.stderr else []
    out = subprocess.run([nginx, "-t", "-p", str(tmp_path), *early_log, "-c", str(conf)],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert "syntax is ok" in out.stderr

    # and the check can fail: a broken copy of the site is refused
    (tmp_path / "eha.conf").write_text(site.replace("proxy_buffering off;", "proxy_buffering of;"),
                                       encoding="utf-8")
    out = subprocess.run([nginx, "-t", "-p", str(tmp_path), *early_log, "-c", str(conf)],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode != 0


# -- the guide -------------------------------------------------------------------------------------------
def test_every_eha_command_of_the_guide_parses():
    guide = GUIDE.read_text(encoding="utf-8")
    commands = [c for block in _code_blocks(guide) for c in _eha_commands(block)]
    assert len(commands) >= 10, commands
    for command in commands:
        try:
            args = _parse(command)
        except UsageError as exc:
            pytest.fail(f"eha {shlex.join(command)}: {exc}")
        assert args.command is not None, command
    # the guide's eha serve is the unit's (the instance 8081)
    assert _exec_start_argv(8081)[1:] in commands, "the guide shows the unit's ExecStart"
    named = [c[:2] for c in commands]
    assert ["exercise", "copy-store"] in named and ["serve", "--exercise"] in named
    stored = [c for c in commands if "--store" in c]
    assert {c[1] for c in stored} >= {"results", "token", "extend", "reveal", "codes"}
    for command in commands:
        args = _parse(command)
        for url in (getattr(args, name, None) for name in ("store", "source", "target")):
            if url:
                if is_postgres_url(url):
                    assert shown_url(url) == url, f"a password in the guide's URL: {url}"
                else:
                    # a backup's place in full: sqlite:////PATH (sqlite:///PATH is relative to the working directory)
                    assert url.startswith("sqlite:////") and len(Path(url[len("sqlite:///"):]).parts) > 2, url


def test_every_eha_command_named_in_the_guides_text_exists():
    """`eha SUBCOMMAND --option` in the prose: the subcommand and each option exist."""
    guide = GUIDE.read_text(encoding="utf-8")
    spans = [_flat(s) for s in re.findall(r"`(eha [^`]+)`", guide)]
    assert len(spans) >= 3 and any("--nginx-config" in s for s in spans)
    for span in spans:
        parser, named, rest = _subcommand(shlex.split(span)[1:])
        assert named, f"`{span}`: no eha subcommand"
        options = {w.split("=", 1)[0] for w in rest if w.startswith("--")}
        unknown = options - set(parser._option_string_actions)
        assert not unknown, f"`{span}`: eha {' '.join(named)} has no {sorted(unknown)}"


def test_the_guide_parser_can_fail():
    """The extraction finds commands, and a command with a wrong option is refused."""
    block = "sudo -u eha -H /opt/eha/venv/bin/eha exercise results class.json --stroe x && echo\n"
    (command,) = _eha_commands(block)
    assert command == ["exercise", "results", "class.json", "--stroe", "x"]
    with pytest.raises(UsageError):
        _parse(command)


def test_the_guides_messages_are_the_servers(tmp_path):
    """The messages the guide quotes are the ones eha prints (the variable parts left out)."""
    import psycopg

    from eha_app.runtime import store_backend

    guide = _flat(GUIDE.read_text(encoding="utf-8"))
    url = "postgresql://eha@db.example.edu:5432/eha_lab"
    backend = PostgresBackend(url)
    detail = "DETAIL-OF-THE-DRIVER"
    said = [
        str(backend._failure(psycopg.OperationalError(detail))),
        str(backend._failure(psycopg.OperationalError(f"{detail} password authentication failed"))),
        str(backend._failure(psycopg.OperationalError(f'{detail} database "eha_lab" does not exist'))),
    ]
    newer = str(backend.newer(3, "eha 0.3.0"))
    said.append(newer.replace(f"this eha {store_backend._eha_version()} ", f"this eha {detail} "))
    for message in said:
        for part in re.split(r"\([^()]*" + detail + r"[^()]*\)|" + detail, message):
            fragment = part.strip(" ,;:(")
            if len(fragment) > 4:
                assert fragment in guide, f"the guide does not say: {fragment!r}\n(eha: {message})"
    # the lines of the journal and of a student's page the guide quotes
    quoted = {
        "eha_app/runtime/store_backend.py": ["the server keeps serving and tries again",
                                             "needs the PostgreSQL driver psycopg: pip install 'eha[postgresql]'",
                                             "is not empty"],
        "eha_app/runtime/outbox.py": ["hand-in(s) left waiting by this server's last run are saved as soon as the "
                                      "database answers"],
        "eha_app/sections/handin.py": ["Your hand-in is waiting to be saved."],
        "eha_app/sections/work.py": ["Your work waits to be kept", "Your work is kept again"],
    }
    for source, fragments in quoted.items():
        texts = _string_literals(ROOT / source)
        for fragment in fragments:
            assert any(fragment in text for text in texts), f"{source} no longer says {fragment!r}"
            assert _flat(fragment) in guide, f"the guide does not quote {fragment!r}"


def _string_literals(path: Path) -> list[str]:
    """The strings of a Python file as the program has them (adjacent literals joined; an f-string's
    values as {})."""
    import ast

    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            out.append(node.value)
        elif isinstance(node, ast.JoinedStr):
            out.append("".join(v.value if isinstance(v, ast.Constant) else "{}" for v in node.values))
    return out


def test_the_guide_keeps_its_figures_section():
    guide = GUIDE.read_text(encoding="utf-8")
    section = guide.split("## Measured class size per machine", 1)
    assert len(section) == 2, "the section of measured figures"
    assert "python benchmarks/bench_hosts.py" in section[1]
    assert guide.count("<!-- FIGURES -->") <= 1
    assert not re.search(r"\bTODO\b|\bXXX\b|\bFIXME\b", guide)
