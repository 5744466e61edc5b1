"""A link copied from the address bar opens another session with the same settings and the same results."""

from tests.ui.browser_helpers import text_of, wait_until


def download_csv(page) -> str:
    with page.expect_download() as download:
        page.get_by_role("button", name="Download CSV").click()
    return open(download.value.path(), encoding="utf-8").read()


def test_a_copied_link_reproduces_the_setup_and_the_results(browser, server):
    first = browser.new_context(viewport={"width": 1366, "height": 900}, accept_downloads=True)
    second = browser.new_context(viewport={"width": 1366, "height": 900}, accept_downloads=True)
    try:
        a = first.new_page()
        a.goto(server)
        a.wait_for_selector(".eha-field-M input", timeout=60_000)
        a.locator(".eha-field-M input").fill("6000")
        wait_until(lambda: "286.7" in text_of(a, ".eha-derived"), message="M = 6000 in use")
        a.locator(".bk-header .bk-tab", has_text="2. Simulation").first.click()
        a.wait_for_selector(".eha-sim-info >> text=nonlinear model")
        a.locator(".eha-field-u_amplitude input[type=text]").fill("3")
        a.locator(".eha-field-d_kind select").select_option("white noise")
        a.wait_for_selector(".eha-sim-info >> text=white noise")
        wait_until(lambda: "3 sin(4πt)" in text_of(a, ".eha-sim-info"), message="the custom run")
        link = a.url
        assert "M=6000" in link and "u_amplitude=3" in link and "tab=2" in link
        csv_a = download_csv(a)

        b = second.new_page()
        b.goto(link)
        b.wait_for_selector(".eha-sim-info >> text=white noise", timeout=60_000)
        assert b.locator(".eha-field-u_amplitude input[type=text]").input_value() == "3"
        wait_until(lambda: "3 sin(4πt)" in text_of(b, ".eha-sim-info"), message="the same run")
        assert download_csv(b) == csv_a                              # the same results, sample for sample
        b.locator(".bk-header .bk-tab", has_text="1. Parameters").first.click()
        assert b.locator(".eha-field-M input").input_value() == "6000"

        c = second.new_page()                                          # a bad value in a link: its message
        c.goto(server + "?M=-5&tab=1")
        c.wait_for_selector(".eha-error-M", timeout=60_000)
        wait_until(lambda: "M = -5 kg is not allowed" in text_of(c, ".eha-error-M"), message="the message")
    finally:
        first.close()
        second.close()
