"""Screenshots of each tab after a run, as a student sees them (1366 x 768, or ``--width``).

Serves the app, drives Debian's headless Chromium with Playwright and writes
PNGs to assets/screenshots/. Run:  python tools/screenshots.py [--out DIR]
"""

from __future__ import annotations

import argparse
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

from playwright.sync_api import sync_playwright

ROOT = Path(__file__).resolve().parents[1]
ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
        "--no-first-run"]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_served(url: str, tries: int = 300) -> None:
    """Until the server answers ``url`` (its first start compiles the kernels)."""
    for _ in range(tries):
        try:
            urllib.request.urlopen(url, timeout=2)
            return
        except OSError:
            time.sleep(0.2)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--out", default=str(ROOT / "assets" / "screenshots"))
    ap.add_argument("--chromium", default="/usr/bin/chromium")
    ap.add_argument("--width", type=int, default=1366, help="the window's width in px (800: a small laptop)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    port = free_port()
    eha = Path(sys.executable).with_name("eha")
    server = subprocess.Popen([str(eha), "serve", "--port", str(port), "--address", "127.0.0.1"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    url = f"http://127.0.0.1:{port}/eha"
    try:
        wait_served(url)
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=args.chromium, args=ARGS)
            page = browser.new_page(viewport={"width": args.width, "height": 768})
            page.goto(url)
            page.wait_for_selector("text=Reset to paper defaults", timeout=60_000)
            page.wait_for_selector(".eha-derived >> text=Transfer functions", timeout=60_000)

            def tab(name):
                page.locator(".bk-header .bk-tab", has_text=name).first.click()

            page.screenshot(path=out / "1_parameters.png")
            tab("2. Simulation")
            page.wait_for_selector(".eha-run-count >> text=run 1", timeout=60_000)
            page.get_by_role("button", name="All four cases").click()
            page.wait_for_selector(".eha-run-count >> text=run 2")
            page.get_by_role("button", name="Compare both").click()
            page.wait_for_selector(".eha-run-count >> text=run 3")
            page.screenshot(path=out / "2_simulation_compare.png")
            tab("3. Identification")
            page.get_by_role("button", name="Run least squares").click()
            page.locator(".eha-lse-table table").wait_for(timeout=60_000)
            page.screenshot(path=out / "3a_least_squares.png")
            page.get_by_role("button", name="Run all four scenarios (Table 4)").click()
            page.wait_for_selector("text=Table 4: four scenarios", timeout=60_000)
            page.locator(".eha-table4-pane").scroll_into_view_if_needed()
            page.screenshot(path=out / "3b_table4.png")
            page.locator(".bk-header .bk-tab", has_text="Frequency domain").first.click()
            page.get_by_role("button", name="Run experiment and estimate").click()
            page.wait_for_selector("text=Backed-out parameters", timeout=120_000)
            page.locator(".bk-header .bk-tab", has_text="Fig. 12 Bode").first.click()
            page.wait_for_timeout(500)  # let the newly shown figure lay out before the picture
            page.screenshot(path=out / "3c_frequency_bode.png")
            page.locator(".eha-backout").scroll_into_view_if_needed()
            page.screenshot(path=out / "3d_backout.png")
            # the black-box models: ARX(2, 2, 1) on the closed loop, then the orders chosen from a table
            page.locator(".bk-header .bk-tab", has_text="Black-box models").first.click()
            page.locator(".eha-bb-form").first.wait_for(state="visible", timeout=60_000)
            page.get_by_role("button", name="Run black-box estimation").click()
            page.locator(".eha-bb-status", has_text="estimated in").wait_for(timeout=120_000)
            page.wait_for_timeout(500)
            page.screenshot(path=out / "3e_blackbox.png", full_page=True)
            page.locator(".eha-field-bb_choose select").select_option("select")
            page.get_by_role("button", name="Run black-box estimation").click()
            page.locator(".eha-bb-selection").first.wait_for(state="visible", timeout=120_000)
            page.wait_for_timeout(500)
            page.screenshot(path=out / "3f_blackbox_selection.png", full_page=True)
            page.get_by_role("button", name="Put on the model board").click()
            page.locator(".bk-header .bk-tab", has_text="Frequency domain").first.click()
            # a second estimate, from the linearised plant: its fast pole near -385 rad/s is weakly determined
            page.locator(".eha-freq-form select").nth(1).select_option("linear")
            page.get_by_role("button", name="Run experiment and estimate").click()
            page.wait_for_selector(".eha-freq-summary >> text=linearised model's data", timeout=120_000)
            # the model board: the least squares (LS1), the transfer functions (H1, H2), the references
            page.locator(".bk-header .bk-tab", has_text="Model board").first.click()
            page.wait_for_selector(".eha-board-fits >> text=H2", timeout=60_000)
            page.wait_for_timeout(500)
            page.screenshot(path=out / "4a_board_fit.png")
            page.locator(".eha-board-views .bk-tab", has_text="Poles and zeros").first.click()
            page.wait_for_timeout(500)
            page.screenshot(path=out / "4b_board_poles_zeros.png")
            page.locator(".eha-board-views .bk-tab", has_text="Bode").first.click()
            page.wait_for_timeout(500)
            page.screenshot(path=out / "4c_board_bode.png")
            page.locator(".bk-header .bk-tab", has_text="Study over seeds").first.click()
            page.get_by_role("button", name="Run the study").click()
            page.wait_for_selector(".eha-study-status >> text=100 of 100 seeds", timeout=120_000)
            page.wait_for_timeout(500)
            page.screenshot(path=out / "4d_study.png")
            browser.close()
    finally:
        server.terminate()
    print("\n".join(str(p) for p in sorted(out.glob("*.png"))))


if __name__ == "__main__":
    main()
