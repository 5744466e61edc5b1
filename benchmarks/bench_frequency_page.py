"""The frequency-domain experiment as a student sees it: click -> page updated, in a real browser.

Serves the app (``eha serve`` on a free port, or ``--url``), opens headless
Chromium, goes to tab 3 -> "Frequency domain", shows a figure tab (default
Fig. 12, the Bode diagram; ``--visit-all`` first opens every figure tab, as
a student who looked at everything) and runs the experiment once to build
the figure (reported apart: "first run"). Then, N times: types a new seed,
waits until the page is idle (Fig. 8 previewed, no message for 0.4 s) and
clicks "Run experiment and estimate". Measured in the page, from the click
event's time stamp, each to the first animation frame after it happened:

  summary   the summary says "Validation on a fresh excitation (seed S+1)"
  fig       the shown figure's canvas painted with the new data (Fig. 12:
            the magnitude plot)
  patch     the server's answer (the document patch with the result) arrived

and the server's compute time as the page reports it ("Experiment,
estimation and validation in 0.17 s": the job's run time in its worker).
The page overhead is click -> page (the later of summary and fig) minus
that compute time: what the network, the server's page update and the
browser add. The last line reads

    freq_click_to_page_ms_median=<ms> max=<ms> server_compute_ms=<median ms>

Run:  python benchmarks/bench_frequency_page.py [--runs 8] [--figure "Fig. 8"] [--visit-all]
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import statistics
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FIGURE_TABS = ("Fig. 8", "Fig. 9", "Fig. 11", "Fig. 12 Bode", "Fig. 13", "Residuals")
#: the figure whose canvas is watched, for each figure tab: (title starts with, or the y axis label)
_WATCHED = {"Fig. 8": "Excitation", "Fig. 9": "Position x", "Fig. 11": "Measured and simulated",
            "Fig. 12": "Bode diagram", "Fig. 13": "Validation", "Residuals": "Residual autocorrelation"}
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--no-first-run", "--disable-sync"]

#: before the page loads: the arrival time of every websocket message
JS_INIT = """(() => {
  window.__ehaWs = [];
  const Native = window.WebSocket;
  window.WebSocket = function (...args) {
    const ws = new Native(...args);
    ws.addEventListener('message', ev => window.__ehaWs.push([performance.now(),
        typeof ev.data === 'string' ? ev.data.length : (ev.data.byteLength ?? ev.data.size ?? 0)]));
    return ws;
  };
  window.WebSocket.prototype = Native.prototype;
  Object.assign(window.WebSocket, {CONNECTING: 0, OPEN: 1, CLOSING: 2, CLOSED: 3});
})();"""

#: before each click: watch the summary and the figure; resolves to the times (ms since the click)
JS_ARM = r"""([seedText, figTitle]) => {
  const frame = () => new Promise(r => requestAnimationFrame(() => r(performance.now())));
  const find = (root, cls) => {
    for (const el of root.querySelectorAll('*')) {
      if (el.classList.contains(cls)) return el;
      if (el.shadowRoot) { const f = find(el.shadowRoot, cls); if (f) return f; }
    }
    return null;
  };
  const views = [];
  const walk = v => { if (!v || views.includes(v)) return; views.push(v);
                      for (const c of (v.child_views ?? [])) walk(c); };
  for (const root of (Bokeh.index.roots ?? Object.values(Bokeh.index))) walk(root);
  const title = v => String(v.model?.title?.text ?? '');
  const label = v => String(v.model?.left?.[0]?.axis_label ?? '');
  const plot = views.find(v => v.model?.type === 'Figure' && (title(v).startsWith(figTitle)
                                                                 || label(v).startsWith(figTitle)));
  const state = window.__ehaRun = {click: null, summary: null, fig: null, patch: null, wsBefore: 0};
  state.wsBefore = window.__ehaWs.length;
  document.addEventListener('click', ev => { if (state.click === null) state.click = ev.timeStamp; },
                            {capture: true, once: true});
  const summary = find(document, 'eha-freq-summary');
  const seen = () => summary && (summary.shadowRoot ?? summary).textContent.includes(seedText);
  const obs = new MutationObserver(() => {
    if (state.summary === null && seen()) { state.summary = 0; frame().then(t => { state.summary = t; }); }
  });
  obs.observe(summary.shadowRoot ?? summary, {subtree: true, childList: true, characterData: true});
  if (plot) {
    const source = plot.model.renderers.find(r => r.data_source)?.data_source;
    const before = source?.data;
    const paint = plot._actual_paint;
    plot._actual_paint = function (...args) {
      const out = paint.apply(this, args);
      if (state.fig === null && source && source.data !== before) {
        state.fig = 0; frame().then(t => { state.fig = t; });
      }
      return out;
    };
  }
  return Boolean(plot);
}"""

JS_RESULT = """() => {
  const s = window.__ehaRun;
  if (s.click === null || !s.summary || (s.fig === 0)) return null;
  const big = window.__ehaWs.slice(s.wsBefore).find(([t, n]) => t > s.click && n > 2000);
  return {summary: s.summary - s.click, fig: s.fig ? s.fig - s.click : null,
          patch: big ? big[0] - s.click : null};
}"""

#: Fig. 8 shows the excitation of the seed typed (its title is drawn on the canvas: read the model)
JS_PREVIEWED = """(seedText) => [...Bokeh.documents[0].all_models].some(
    m => m.type === 'Title' && String(m.text).startsWith('Excitation') && String(m.text).endsWith(seedText))"""

#: the page is idle: no websocket message for ``quiet`` ms and animation frames on time
JS_IDLE = """async (quiet) => {
  const frame = () => new Promise(r => requestAnimationFrame(r));
  for (;;) {
    const t0 = performance.now(); await frame(); await frame();
    const last = window.__ehaWs.length ? window.__ehaWs[window.__ehaWs.length - 1][0] : 0;
    if (performance.now() - t0 < 60 && performance.now() - last > quiet) return true;
    await new Promise(r => setTimeout(r, 50));
  }
}"""


# the same server as the classroom benchmark's (run as a script from benchmarks/, or imported)
if __package__:
    from .bench_classroom import Server  # noqa: E402
else:
    from bench_classroom import Server  # noqa: E402


def _chromium(path: str | None) -> str:
    path = path or os.environ.get("EHA_CHROMIUM") or shutil.which("chromium") or "/usr/bin/chromium"
    if not Path(path).exists():
        raise SystemExit(f"bench_frequency_page: Chromium not found at {path} (set --chromium or EHA_CHROMIUM)")
    return path


def _compute_s(summary_text: str) -> float:
    m = re.search(r"Experiment, estimation and validation in ([0-9.]+) s", summary_text)
    return float(m.group(1)) if m else float("nan")


def run(url: str, args) -> list[dict]:
    from playwright.sync_api import sync_playwright

    figure = next((t for t in FIGURE_TABS if t.startswith(args.figure)), None)
    if figure is None:
        raise SystemExit(f"bench_frequency_page: --figure {args.figure!r} is not one of {FIGURE_TABS}")
    watched = _WATCHED[next(k for k in _WATCHED if figure.startswith(k))]
    rows = []
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=_chromium(args.chromium), args=CHROMIUM_ARGS)
        page = browser.new_page(viewport={"width": 1366, "height": 900})
        page.add_init_script(JS_INIT)
        page.goto(url)
        page.wait_for_selector("text=Reset to paper defaults", timeout=120_000)
        page.locator(".bk-header .bk-tab", has_text="3. Identification").first.click()
        page.locator(".bk-tab", has_text="Frequency domain").first.click()
        page.wait_for_selector(".eha-run-freq button", timeout=60_000)
        # the seed is among the excitation's details, folded when the tab opens
        seed_box = page.locator(".eha-freq-form #eha-input-freq_seed")
        if not seed_box.is_visible():
            page.locator(".eha-freq-form summary", has_text="Excitation details").click()
        button = page.get_by_role("button", name="Run experiment and estimate")

        def one_run(seed: int) -> dict:
            seed_box.fill(str(seed))
            seed_box.press("Enter")
            page.wait_for_function(JS_PREVIEWED, arg=f"seed {seed}", timeout=60_000, polling=50)
            page.evaluate(JS_IDLE, 400)
            found = page.evaluate(JS_ARM, [f"Validation on a fresh excitation (seed {seed + 1})", watched])
            button.click()
            page.wait_for_function(JS_RESULT, timeout=120_000, polling=50)
            out = page.evaluate(JS_RESULT)
            if found and out["fig"] is None:        # the figure has the new data but was painted later
                page.wait_for_function("() => window.__ehaRun.fig > 0", timeout=30_000, polling=50)
                out = page.evaluate(JS_RESULT)
            out["compute"] = 1e3 * _compute_s(page.locator(".eha-freq-summary").first.evaluate(
                "el => (el.shadowRoot ?? el).textContent"))
            out["page"] = max(out["summary"], out["fig"] or 0.0)
            return out

        if args.visit_all:
            one_run(100)                            # data for every figure
            for tab in FIGURE_TABS:
                page.locator(".bk-tab", has_text=tab).first.click()
                page.evaluate(JS_IDLE, 600)            # the figure is built and drawn
        page.locator(".bk-tab", has_text=figure).first.click()
        first = one_run(200)
        print(f"first run with the tab shown (builds its figure unless built before): click -> page "
              f"{first['page']:.0f} ms, server compute {first['compute']:.0f} ms")
        print(f"{'run':>4s} {'summary':>8s} {'figure':>8s} {'page':>8s} {'patch':>8s} {'compute':>8s} "
              f"{'overhead':>9s}   [ms from the click]")
        for i in range(args.runs):
            r = one_run(i + 1)
            rows.append(r)
            fig = "-" if r["fig"] is None else f"{r['fig']:.0f}"
            patch = "-" if r["patch"] is None else f"{r['patch']:.0f}"
            print(f"{i + 1:4d} {r['summary']:8.0f} {fig:>8s} {r['page']:8.0f} {patch:>8s} {r['compute']:8.0f} "
                  f"{r['page'] - r['compute']:9.0f}", flush=True)
        browser.close()
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=8, help="measured runs (default 8)")
    ap.add_argument("--figure", default="Fig. 12", help="the figure tab shown while running (default Fig. 12)")
    ap.add_argument("--visit-all", action="store_true", help="open every figure tab first (all figures built)")
    ap.add_argument("--url", help="a running server's app URL (default: start eha serve)")
    ap.add_argument("--chromium", help="Chromium's path (default: EHA_CHROMIUM, chromium on PATH, /usr/bin/chromium)")
    args = ap.parse_args(argv)
    print(f"machine: {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}; figure tab {args.figure!r}"
          f"{', every figure built' if args.visit_all else ''}; {args.runs} runs")
    server = None if args.url else Server()
    try:
        rows = run(args.url or server.url, args)
    finally:
        if server is not None:
            server.stop()

    def med(key):
        vals = [r[key] for r in rows if r[key] is not None]
        return (statistics.median(vals), max(vals)) if vals else (float("nan"), float("nan"))

    (s_med, s_max), (f_med, f_max), (p_med, p_max) = med("summary"), med("fig"), med("page")
    (c_med, _), (w_med, _) = med("compute"), med("patch")
    overhead = statistics.median(r["page"] - r["compute"] for r in rows)
    print(f"click -> summary      median {s_med:6.0f} ms   max {s_max:6.0f} ms")
    print(f"click -> {args.figure} drawn  median {f_med:6.0f} ms   max {f_max:6.0f} ms")
    print(f"click -> page (both)  median {p_med:6.0f} ms   max {p_max:6.0f} ms")
    print(f"click -> result patch arrived  median {w_med:6.0f} ms (the server's part, network included)")
    print(f"server compute (the page's own figure) median {c_med:6.0f} ms; page overhead (page - compute) "
          f"median {overhead:6.0f} ms; ratio page / compute {p_med / c_med:.1f}")
    print(f"freq_click_to_page_ms_median={p_med:.0f} max={p_max:.0f} server_compute_ms={c_med:.0f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
