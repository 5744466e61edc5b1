"""Screenshots of a lab session, as the teacher and a student see them (1366 x 768).

Makes an exercise with a roster of four, serves it, lets three students join with their codes and
hand in (two from the least squares, one from the frequency domain's back-out), then photographs
the teacher's dashboard, a student's join page and a student's hand-in. Writes PNGs to
assets/screenshots/. Run:  python tools/lab_screenshots.py [--out DIR]
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from playwright.sync_api import sync_playwright

sys.path.insert(0, str(Path(__file__).resolve().parent))
from screenshots import ARGS, ROOT, free_port, wait_served  # noqa: E402

ROSTER = ("id,name\ns1234567,Ada Lovelace\ns2345678,Alan Turing\ns3456789,Grace Hopper\n"
          "s4567890,Edsger Dijkstra\n")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--out", default=str(ROOT / "assets" / "screenshots"))
    ap.add_argument("--chromium", default="/usr/bin/chromium")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    eha = Path(sys.executable).with_name("eha")
    work = Path(tempfile.mkdtemp())
    (work / "class.csv").write_text(ROSTER, encoding="utf-8")
    lab = work / "lab3.json"
    subprocess.run([str(eha), "exercise", "new", "--roster", str(work / "class.csv"), "--title", "Lab 3: identify "
                    "your actuator", "--deadline", "2099-12-01T17:00", "--out", str(lab)], check=True,
                   stdout=subprocess.DEVNULL)
    codes = subprocess.run([str(eha), "exercise", "codes", str(lab)], check=True, capture_output=True, text=True)
    code = {line.split()[-1]: line.split()[0] for line in codes.stdout.splitlines()}
    port = free_port()
    log = open(work / "server.log", "w")
    server = subprocess.Popen([str(eha), "serve", "--port", str(port), "--exercise", str(lab)], stdout=log,
                              stderr=subprocess.STDOUT)
    url = f"http://127.0.0.1:{port}/eha"
    try:
        wait_served(url)
        token = re.search(r"/teacher\?token=([0-9a-f]+)", (work / "server.log").read_text()).group(1)
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=args.chromium, args=ARGS)

            def student(sid, route):
                page = browser.new_page(viewport={"width": 1366, "height": 768})
                page.goto(url)
                page.locator(".eha-join-code input").fill(code[sid], timeout=60_000)
                if sid == "s1234567":
                    page.screenshot(path=out / "5a_join.png")
                page.get_by_role("button", name="Start").click()
                page.locator(".eha-student").wait_for(timeout=60_000)
                page.locator(".bk-header .bk-tab", has_text="3. Identification").first.click()
                if route == "lse":
                    page.get_by_role("button", name="Run least squares").click()
                    page.locator(".eha-lse-table table").wait_for(state="visible", timeout=90_000)
                    page.get_by_role("button", name="Hand in these estimates").click()
                    page.locator(".eha-verdict", has_text="Handed in").wait_for(timeout=60_000)
                else:
                    page.locator(".bk-tab", has_text="Frequency domain").first.click()
                    page.get_by_role("button", name="Run experiment and estimate").click()
                    page.wait_for_selector(".eha-freq-summary >> text=Validation", timeout=90_000)
                    page.get_by_role("button", name="Hand in the back-out's βe").click()
                    page.locator(".eha-verdict", has_text="Handed in").wait_for(timeout=60_000)
                return page

            first = student("s1234567", "lse")
            first.screenshot(path=out / "5b_handed_in.png")
            student("s2345678", "lse")
            student("s3456789", "frequency")
            dash = browser.new_page(viewport={"width": 1366, "height": 768})
            dash.goto(f"http://127.0.0.1:{port}/teacher?token={token}")
            dash.locator(".eha-dash-roster", has_text="Grace Hopper").wait_for(timeout=60_000)
            dash.locator(".eha-dash-roster", has_text="transfer function").wait_for(timeout=30_000)
            time.sleep(1.0)
            dash.screenshot(path=out / "5c_dashboard.png")
            browser.close()
    finally:
        server.terminate()
        server.wait(timeout=30)
    print("\n".join(str(p) for p in sorted(out.glob("5*.png"))))


if __name__ == "__main__":
    main()
