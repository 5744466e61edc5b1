"""Past one machine: two "hosts" behind one nginx, the lab's state in PostgreSQL, one host lost mid-lab.

A host (:class:`benchmarks.hosts.Host`) is a process group of its own (``start_new_session=True``) with a
working directory of its own (a copy of the exercise file in each) and a port of its own, running ``eha serve
--exercise class.json --store postgresql://... --behind-proxy --workers 1``. nginx
(:class:`benchmarks.hosts.Nginx`, the configuration of
:func:`eha_app.runtime.serving.nginx_standalone_config`) sends each browser, by its affinity cookie, to one of
them. Twenty students of a roster (3 hand-ins each) type a value of L0 of their own, run least squares and
hand in; while they hand in a second time, host 1's whole process group is SIGKILLed. Its students reload (the
same cookie jar): nginx sends them to host 2, they join with their code again and find their work there (their
own L0 back in the field, the least squares run again), and hand in again until the third hand-in, counted
over both hosts, is the last one taken.

Checked: every hand-in a student saw confirmed ("Handed in (hand-in k of 3 allowed ...") is in the database
once, the k shown is the database's count, nothing is stored twice (one row per page key); a fourth is
refused on host 2 for a student who handed in on host 1 before; the teacher's dashboard opened directly on
either host shows the class of both, and a hand-in made on one host appears on the other's dashboard
within its poll interval.
"""

from __future__ import annotations

import asyncio
import os
import random
import re
import time

import pytest

from benchmarks.classroom_client import Student, StudentSession, wait_served
from benchmarks.hosts import NGINX, Host, Nginx
from tests.serve.conftest import free_port

pytestmark = pytest.mark.skipif(NGINX is None, reason="nginx not found: apt-get install -y nginx "
                                                       "(the README's test command installs it)")

STUDENTS = 20
ATTEMPTS = 3
PARAM = "L0"
TIMEOUT = 120.0
_HANDED_IN = re.compile(r"Handed in \(hand-in (\d+) of (\d+) allowed")
_USED = re.compile(r"hand-ins: (\d+) of (\d+) used")
_CELL = re.compile(r"<td[^>]*>(.*?)</td>", re.S)


def own_value(i: int) -> str:
    """What student i (from 0) types into L0 [mm]: a value of their own, recognisable in their kept work."""
    return f"{311 + 0.3 * i:.1f}"


# -- the students and the teacher, at the protocol level ------------------------------------------------

class LabStudent(Student):
    """A student who hands in the least squares' estimates and reads what the page says of it."""

    def l0(self) -> str | None:
        values = self.form(self.FORM).attributes.get("values") or {}
        return None if values.get(PARAM) is None else str(values[PARAM])

    def rules(self) -> str:
        found = self.find(css="eha-lab-rules-pane")
        return found[0].text() if found else ""

    async def lse_handin_button(self, timeout: float):
        """The least squares' hand-in button, once the page has a result to hand in or says why not."""
        await self.show_tab(2, self.IDENT_TABS, timeout)
        await self.show_subtab(self.IDENT_TABS, self.LSE_SUBTAB, "eha-lse-table", timeout)
        button = self.button("Hand in these estimates")
        await self.wait_for(lambda: not button.get("disabled") or self.tip(button).startswith("no hand-in now"),
                            timeout, "the hand-in button on (a result) or a refusal in its tip")
        return button

    async def hand_in_lse(self, timeout: float = TIMEOUT, *, force: bool = False) -> tuple[str, str]:
        """Press "Hand in these estimates" (``force``: even when it is off, as a crafted page could);
        ("handed", k), ("refused", why), ("off", tip) or ("waiting", text)."""
        button = await self.lse_handin_button(timeout)
        if button.get("disabled") and not force:
            return "off", self.tip(button)
        panes = self.find(css="eha-verdict")
        before = {m.id: (m.get("visible"), m.text()) for m in panes}
        await self.click(button)
        asked = False

        def outcome():
            nonlocal asked
            for m in panes:
                now = (m.get("visible"), m.text())
                if now != before[m.id] and now[0] and now[1].strip():
                    return now[1]
            confirm = self.find(css="eha-handin-confirm")
            if confirm and confirm[0].get("visible") and not asked:
                asked = True
                return "ask"
            return None

        while True:
            text = await self.wait_for(outcome, timeout, "the hand-in's verdict")
            if text != "ask":
                break
            # an estimate out of its physical bounds: the page asks first; the student hands it in anyway
            await self.click(self._one("button 'Hand in anyway'", self.find(css="eha-handin-anyway")))
        plain = re.sub(r"\s+", " ", re.sub(r"<[^>]+>", " ", text))
        handed = _HANDED_IN.search(plain)
        if handed:
            assert int(handed.group(2)) == ATTEMPTS, plain
            return "handed", handed.group(1)
        if "Not handed in:" in plain or "Cannot be handed in:" in plain:
            return "refused", plain
        if "waiting to be saved" in plain:
            return "waiting", plain
        raise AssertionError(f"{self.name}: a verdict neither taken nor refused: {plain[:300]}")


class Dashboard(StudentSession):
    """The teacher's dashboard opened on one host directly (its own port, not through nginx)."""

    def __init__(self, port: int, token: str):
        from eha_app.runtime.teacher_access import COOKIE, cookie_value

        super().__init__(f"http://127.0.0.1:{port}/teacher", name=f"dashboard:{port}", timeout=TIMEOUT)
        self.cookies[COOKIE] = cookie_value(token)

    def counts(self) -> dict[str, int]:
        """The class table: each student's id -> hand-ins, as the page shows them now."""
        found = self.find(css="eha-dash-roster")
        out = {}
        for row in (found[0].text() if found else "").split("<tr>"):
            cells = _CELL.findall(row)
            if len(cells) > 5 and cells[4].strip().isdigit():
                out[re.sub(r"<[^>]+>", "", cells[0]).strip()] = int(cells[4])
        return out

    async def shows(self, expected: dict[str, int], timeout: float) -> float:
        """Seconds until the class table shows ``expected`` (id -> hand-ins) for those ids."""
        t0 = time.perf_counter()
        await self.wait_for(lambda: all(self.counts().get(s) == n for s, n in expected.items()), timeout,
                            f"the dashboard showing {expected}")
        return time.perf_counter() - t0


# -- the test -------------------------------------------------------------------------------------------

def test_two_hosts_share_the_lab_and_one_dies_mid_lab(pg_url, tmp_path):
    from eha_app.dashboard import POLL_MS
    from eha_app.runtime.handins import HandIns
    from eha_app.runtime.teacher_access import issued
    from eha_core.exercise import Exercise

    roster = [(f"s{i + 1}", f"Student {i + 1}") for i in range(STUDENTS)]
    ex = Exercise.new(hide=("M", "B", "Af", "beta_e"), tolerance={"B": 0.10}, title="Lab past one machine",
                      roster=roster, attempts=ATTEMPTS)
    exercise = tmp_path / "class.json"
    ex.save(exercise)
    ids = [e.id for e in ex.roster]
    codes = [ex.join_code(sid) for sid in ids]
    store = HandIns(exercise, store=pg_url)

    listen = free_port()
    hosts: list[Host] = []
    front = None
    try:
        # host 2 starts once host 1 has issued the dashboard's link (two hosts started at the same moment on
        # an empty database each issue one: see test_hosts_started_together_print_one_dashboard_link)
        # the pages come through nginx; the dashboard is opened on each host itself too (its own address)
        origin = f"127.0.0.1:{listen}"
        hosts.append(Host(tmp_path / "host1", exercise, pg_url, origin, own_origin=True))
        hosts[0].wait_for_link()
        hosts.append(Host(tmp_path / "host2", exercise, pg_url, origin, own_origin=True))
        for h in hosts:
            h.wait()
        h1, h2 = hosts
        front = Nginx(tmp_path / "nginx", listen, [h1.address, h2.address])
        wait_served(None, front.url, 30)
        now = issued(ex, store)
        assert now is not None, "no dashboard token was issued"
        token = now.token
        # the link each host printed is the one in the database
        for h in hosts:
            assert h.links() == [token], (h.address, h.links(), token)

        report = asyncio.run(_lab(front.url, h1, h2, ids, codes, token, store, POLL_MS / 1000))
        print("\n" + "\n".join(report))

        # the hosts' logs: host 2 took the class without a fault; nginx only found host 1 gone
        assert "Traceback" not in h2.log_text(), h2.log_text()[-4000:]
        errors = front.errors()
        assert all(h1.address in ln and "Connection refused" in ln for ln in errors), errors[:5]
    finally:
        if front is not None:
            front.stop()
        for h in hosts:
            h.stop()


async def _lab(url: str, h1: Host, h2: Host, ids: list[str], codes: list[str], token: str, store,
               poll_s: float) -> list[str]:
    rng = random.Random(7)
    report: list[str] = []
    # per student: what their pages said of each hand-in, in order: ("handed", k) or ("lost", why)
    seen: dict[str, list[tuple[str, str]]] = {s: [] for s in ids}
    students = [LabStudent(url, name=f"student {i + 1}", code=codes[i], param_name=PARAM, timeout=TIMEOUT)
                for i in range(len(ids))]
    dash1, dash2 = Dashboard(h1.port, token), Dashboard(h2.port, token)
    await dash1.open()
    await dash2.open()

    async def hand_in(i: int, st: LabStudent, **kw) -> tuple[str, str]:
        try:
            out = await st.hand_in_lse(**kw)
        except Exception as exc:  # noqa: BLE001 - the host died under it: noted, checked against the database
            seen[ids[i]].append(("lost", f"{type(exc).__name__}: {exc}"[:200]))
            return "lost", str(exc)
        if out[0] == "handed":
            seen[ids[i]].append(out)
        assert out[0] != "waiting", f"{st.name}: {out[1][:300]}"    # the database never went away here
        return out

    # 1. the class: open and join through nginx, type L0, least squares, hand in once
    async def first(i: int, st: LabStudent):
        await asyncio.sleep(rng.uniform(0, 3))
        await st.open()
        await st.change_parameter(PARAM, own_value(i))
        await st.least_squares()
        assert await hand_in(i, st) == ("handed", "1"), seen[ids[i]]

    t0 = time.perf_counter()
    await asyncio.gather(*(first(i, st) for i, st in enumerate(students)))
    report.append(f"phase 1 (open, L0, least squares, hand-in 1): {time.perf_counter() - t0:.1f} s")
    on = {h.address: [i for i, st in enumerate(students) if st.upstream == h.address] for h in (h1, h2)}
    report.append(f"students per host: {', '.join(f'{a}: {len(v)}' for a, v in on.items())}")
    assert sorted(on[h1.address] + on[h2.address]) == list(range(len(ids))), [st.upstream for st in students]
    assert on[h1.address] and on[h2.address], "both hosts must have students"
    # each page's websocket reached the host that served its page (one dashboard each besides)
    for h in (h1, h2):
        assert h.log_text().count("WebSocket connection opened") == len(on[h.address]) + 1

    # 2. the dashboard on either host shows the whole class, and follows the other host live
    for dash in (dash1, dash2):
        await dash.shows({s: 1 for s in ids}, 3 * poll_s + 10)
    for src, dash in ((on[h1.address][0], dash2), (on[h2.address][0], dash1)):
        out = await hand_in(src, students[src])
        assert out == ("handed", "2"), out
        seconds = await dash.shows({ids[src]: 2}, 3 * poll_s + 10)
        report.append(f"a hand-in of {ids[src]} on {students[src].upstream} on the other host's dashboard after "
                      f"{seconds:.1f} s (poll {poll_s:g} s)")
        assert seconds <= poll_s + 3.0, seconds
    await dash1.close()

    # 3. mid-lab: two students in three hand in again, over 4 s; host 1 is killed 1.5 s in
    again = [i for i in range(len(ids)) if i % 3 != 0 and len(seen[ids[i]]) == 1]

    async def second(i: int):
        await asyncio.sleep(rng.uniform(0, 4))
        await hand_in(i, students[i])

    async def kill_host_1():
        await asyncio.sleep(1.5)
        h1.kill()

    await asyncio.gather(*(second(i) for i in again), kill_host_1())
    assert not h1.alive()
    with pytest.raises(ProcessLookupError):         # nothing of host 1's process group runs
        os.killpg(h1.proc.pid, 0)
    lost = [ids[i] for i in again if seen[ids[i]][-1][0] == "lost"]
    report.append(f"mid-lab: {len(again)} hand in again, host 1 killed; not confirmed: {lost}")
    assert set(lost) <= {ids[i] for i in on[h1.address]}, lost     # only host 1's students lost a press
    for i in on[h2.address]:                    # host 2's students never noticed
        assert all(kind == "handed" for kind, _ in seen[ids[i]]), seen[ids[i]]

    restored: dict[str, str] = {}

    # 4. host 1's students reload (the same cookie jar): nginx sends them to host 2, their work is there,
    #    and they hand in until the third hand-in over both hosts, and no further
    async def come_back(i: int):
        old = students[i]
        await old.close()
        st = LabStudent(url, name=old.name, code=codes[i], param_name=PARAM, timeout=TIMEOUT)
        st.cookies = dict(old.cookies)
        students[i] = st
        await asyncio.sleep(rng.uniform(0, 2))
        await st.open()
        # nginx tried the cookie's host first (X-Eha-Upstream: "host1, host2"), found it gone and went on to host 2
        assert st.upstream.split(", ")[-1] == h2.address, (st.name, st.upstream)
        await st.wait_for(lambda: st.l0() is not None and float(st.l0()) == float(own_value(i)), 60,
                          f"L0 = {own_value(i)} restored")
        note = await st.wait_for(lambda: next((m.text() for m in st.find(css="eha-settings-note")
                                                if "Your work was restored" in m.text()), None), 60,
                                 "the note that the work was restored")
        restored[st.name] = re.sub(r"<[^>]+>", "", note)
        count = len(store.of(ids[i]))
        used = await st.wait_for(lambda: _USED.search(re.sub(r"<[^>]+>", " ", st.rules())), 30, "the rules")
        assert int(used.group(1)) == count, (st.name, used.group(0), count)
        while count < ATTEMPTS:
            kind, k = await hand_in(i, st)
            count = len(store.of(ids[i]))
            assert (kind, k) == ("handed", str(count)), (st.name, kind, k, count)
        # the fourth, counted over both hosts: the button goes off (the page reads the rules again after a
        # hand-in, a moment after its verdict), and a press of it anyway is refused by the database
        button = st.button("Hand in these estimates")
        tip = await st.wait_for(lambda: button.get("disabled") and st.tip(button), 10, "the hand-in button off")
        assert f"you have handed in {ATTEMPTS} of {ATTEMPTS} times allowed" in tip, tip
        assert (await st.hand_in_lse())[0] == "off"
        kind, why = await st.hand_in_lse(force=True)
        assert kind == "refused" and f"{ATTEMPTS} of {ATTEMPTS} times allowed" in why, (kind, why)

    # host 2's own students go on meanwhile: one in three hands in a third time
    async def go_on(i: int):
        await asyncio.sleep(rng.uniform(0, 3))
        out = await hand_in(i, students[i])
        assert out[0] == "handed", out

    t0 = time.perf_counter()
    back = on[h1.address]
    await asyncio.gather(*(come_back(i) for i in back), *(go_on(i) for i in on[h2.address] if i % 3 == 1))
    report.append(f"host 1's {len(back)} students back on host 2 and done: {time.perf_counter() - t0:.1f} s; "
                  f"their pages said e.g. {next(iter(restored.values()), '')!r}")

    # 5. the database: every confirmed hand-in once, the counts shown the database's, 3 at most
    counts = _check_store(store, ids, seen, [ids[i] for i in back], report)

    # the dashboard on host 2 (open all along) shows the final class: those of host 1 too
    seconds = await dash2.shows(counts, poll_s + 10)
    report.append(f"host 2's dashboard (open throughout) showed the database's count of every student "
                  f"{seconds:.1f} s after the last hand-in")
    await dash2.close()
    await asyncio.gather(*(st.close() for st in students), return_exceptions=True)
    return report


def _check_store(store, ids: list[str], seen: dict, back: list[str], report: list[str]) -> dict[str, int]:
    """Every hand-in a page confirmed is in the database once, the "hand-in k" a page showed last is the
    database's count, nobody has more than the attempts, and those of host 1 were refused a fourth on host 2;
    returns each student's hand-ins."""
    rows = store.all()
    counts = {s: sum(1 for r in rows if r.student == s) for s in ids}
    assert {r.student for r in rows} <= set(ids)
    for s in ids:
        handed = [int(k) for kind, k in seen[s] if kind == "handed"]
        lost_here = sum(1 for kind, _ in seen[s] if kind == "lost")
        assert handed == sorted(set(handed)), (s, seen[s])                      # each number once, in order
        # none confirmed and lost, none stored twice: at most the presses lost with host 1 came in besides
        assert len(handed) <= counts[s] <= len(handed) + lost_here, (s, seen[s], counts[s])
        assert counts[s] <= ATTEMPTS, (s, counts[s])
        if seen[s][-1][0] == "handed":
            assert int(seen[s][-1][1]) == counts[s], (s, seen[s], counts[s])
    refusals = store.refusals()
    for s in back:
        assert counts[s] == ATTEMPTS
        assert any(who == s and f"{ATTEMPTS} of {ATTEMPTS}" in why for _t, who, _m, why in refusals), s
    _one_row_per_key(store)
    unconfirmed = sorted(s for s in ids if counts[s] > sum(1 for kind, _ in seen[s] if kind == "handed"))
    report.append(f"database: {len(rows)} hand-ins, per student {counts}; pressed on host 1 as it died, not "
                  f"confirmed, stored: {unconfirmed} (the rest never reached it)")
    return counts


def _one_row_per_key(store) -> None:
    """No hand-in stored twice: every row's page key is its own (a key is made per press of the button)."""
    dup = store._read("SELECT student, key, COUNT(*) FROM handins GROUP BY student, key HAVING COUNT(*) > 1")
    assert not dup, dup
    empty = store._read("SELECT COUNT(*) FROM handins WHERE key = ''")[0][0]
    assert empty == 0, f"{empty} hand-ins without their page's key"


def test_hosts_started_together_print_one_dashboard_link(pg_url, tmp_path):
    from eha_app.runtime.handins import HandIns
    from eha_app.runtime.teacher_access import issued
    from eha_core.exercise import Exercise

    ex = Exercise.new(hide=("M", "B"), roster=[("s1", "Ada Lovelace")])
    exercise = tmp_path / "class.json"
    ex.save(exercise)
    hosts = []
    try:
        hosts = [Host(tmp_path / f"host{k}", exercise, pg_url, f"127.0.0.1:{free_port()}", own_origin=True)
                 for k in (1, 2)]
        printed = [h.wait_for_link() for h in hosts]
        token = issued(ex, HandIns(exercise, store=pg_url)).token
        assert printed == [token, token], (printed, token)
    finally:
        for h in hosts:
            h.stop()
