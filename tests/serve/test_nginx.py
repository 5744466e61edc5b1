"""Past one process: nginx (Debian's) in front of three `eha serve` processes.

The configuration is the one `eha serve --nginx-config` prints: websocket
upgrade, and affinity by a cookie nginx sets on a browser's first request, so
that a page and its websocket reach the same process.
"""

from __future__ import annotations

import shutil
import subprocess

import pytest

from benchmarks.classroom_client import run_students
from eha_app.runtime.serving import nginx_standalone_config
from tests.serve.conftest import free_port, wait_http

NGINX = shutil.which("nginx") or ("/usr/sbin/nginx" if shutil.os.path.exists("/usr/sbin/nginx") else None)
pytestmark = pytest.mark.skipif(NGINX is None, reason="nginx not found: apt-get install -y nginx "
                                                       "(the README's test command installs it)")


@pytest.fixture
def nginx_front(serve, tmp_path):
    listen = free_port()
    backends = [serve("--behind-proxy", "--workers", "1", "--allow-websocket-origin", f"127.0.0.1:{listen}")
                for _ in range(3)]
    work = tmp_path / "nginx"
    work.mkdir()
    conf = work / "nginx.conf"
    conf.write_text(nginx_standalone_config([f"127.0.0.1:{b.port}" for b in backends],
                                            listen=f"127.0.0.1:{listen}", workdir=str(work)))
    test = subprocess.run([NGINX, "-t", "-c", str(conf), "-p", str(work)], capture_output=True, text=True)
    assert test.returncode == 0, test.stderr
    proc = subprocess.Popen([NGINX, "-c", str(conf), "-p", str(work)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.STDOUT)
    url = f"http://127.0.0.1:{listen}/eha"
    try:
        wait_http(url, proc, timeout=30)
        yield url, backends, work
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def test_thirty_students_through_nginx_spread_over_three_processes(nginx_front):
    url, backends, work = nginx_front
    steps = ("open", "param", "tab2", "compare", "freqtab", "freq")
    result = run_students(url, 30, steps, observer=False, spread=1.0, timeout=180)
    for step in steps:
        assert result.ok(step) == 30, (step, result.errors(step)[:3])
    assert result.error_count() == 0
    # every process served some of the class (affinity by a random cookie, hashed consistently: the
    # shares are near but not exactly a third; with 30 students a process gets 2 or more but for
    # a chance of about 1e-3, where ">= 4" failed about once in a hundred runs: 13/14/3 was seen)
    ports = {f"127.0.0.1:{b.port}" for b in backends}
    assert set(result.upstreams) == ports, result.upstreams
    assert min(result.upstreams.values()) >= 2, result.upstreams
    # affinity: each page's websocket reached the process that served the page
    for b in backends:
        log = b.log_text()
        assert "Traceback" not in log
        assert log.count("WebSocket connection opened") == result.upstreams[f"127.0.0.1:{b.port}"]
    assert "[error]" not in (work / "error.log").read_text()
