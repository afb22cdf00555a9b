"""No script injected: the dashboard in headless Chromium with HTML, ``<img onerror>``, ``<svg onload>``,
``<script>`` and ``javascript:`` payloads in every query field of /design and in every name a user can
upload (recording labels, road profile names), the charts hovered. Nothing may run (each payload sets
``window.__pwned`` and the title, or opens a dialog), no element the payload describes may exist (so the
test holds even without the CSP), no script-src violation may be reported (an injected handler the CSP
stopped), and ``document.cookie`` never shows the session.
"""

from __future__ import annotations

from typing import Any
from urllib.parse import urlencode

import pytest
from playwright.sync_api import TimeoutError as PlaywrightTimeout

from finaldrive.service.api.access import COOKIE
from tests.service.processes import Server
from tests.service.svc_helpers import wait_done
from tests.service.web.browser import TOKEN, Page

pytestmark = pytest.mark.slow

RUN = "alert(__pwned=document.title='pwned')"
#: payloads of at most 64 characters (the shortest limit on a name: a profile's)
PAYLOADS = {
    "img-onerror": f"<img src=x onerror={RUN}>",
    "svg-onload": f'"><svg onload="{RUN}">',
    "script": f"<script>{RUN}</script>",
    "javascript-url": f"javascript:{RUN}",
    "a-href": f'<a href="javascript:{RUN}">x',
}
NAMES = list(PAYLOADS.values())
#: records every CSP report of the page and its frames
WATCH = """window.__violations = [];
document.addEventListener("securitypolicyviolation",
                          (e) => window.__violations.push(`${e.violatedDirective} ${e.blockedURI}`));
"""
#: elements and attributes a payload would create if it reached the DOM as HTML
INJECTED = """[...document.querySelectorAll(
    "img, svg:not(.chart-box > svg), script:not([src^='/static/']), iframe:not(#viewer), .tooltip *:not(div, span)"),
  ...[...document.querySelectorAll("*")].filter((e) => [...e.attributes].some((a) => a.name.startsWith("on")
    || (["href", "src", "action", "formaction", "xlink:href"].includes(a.name) && /^\\s*javascript:/i.test(a.value)))),
].map((e) => e.outerHTML.slice(0, 120))"""


def watched(tab: Page) -> list[str]:
    dialogs: list[str] = []
    tab.page.on("dialog", lambda d: (dialogs.append(d.message), d.dismiss()))
    tab.page.add_init_script(WATCH)
    return dialogs


def assert_nothing_ran(tab: Page, dialogs: list[str]) -> None:
    state: dict[str, Any] = tab.page.evaluate(f"""() => ({{
        pwned: window.__pwned ?? null, title: document.title, cookie: document.cookie,
        violations: window.__violations.filter((v) => v.startsWith("script-src")), injected: {INJECTED} }})""")
    assert state["pwned"] is None and state["title"] != "pwned" and dialogs == [], state
    assert state["injected"] == [] and state["violations"] == [], state
    assert TOKEN not in state["cookie"] and COOKIE not in state["cookie"], state


def hover(tab: Page, selector: str, at: tuple[float, float] | None = None) -> str:
    """Move the mouse over the element (its centre, or ``at``) and answer its chart box's tooltip text."""
    element = tab.page.locator(selector)
    tip = element.locator("xpath=../div[contains(@class, 'tooltip')]")
    for attempt in range(5):  # the page may still move (the viewer's frame loading below): hover again
        element.wait_for(state="visible", timeout=10_000)   # a chart is drawn anew when its data change
        box = element.bounding_box()
        if box is None:   # replaced between the two
            continue
        x, y = at if at is not None else (box["width"] / 2, box["height"] / 2)
        element.hover(position={"x": x + attempt, "y": y})
        try:
            tip.wait_for(state="visible", timeout=2000)
            break
        except PlaywrightTimeout:
            continue
    return str(tip.inner_text())


def test_design_page_shows_labels_as_text_in_table_legend_and_tooltips(tab: Page) -> None:
    dialogs = watched(tab)
    # the labels' limit is 80 characters
    label_a, label_b = PAYLOADS["img-onerror"], PAYLOADS["script"] + PAYLOADS["javascript-url"][:16]
    tab.goto("/design?" + urlencode({"road": "flat", "label_a": label_a, "label_b": label_b}))
    tab.ready()
    for prefix, design in (("a", (0, 0.08, 0.093)), ("b", (180, 0.1, 0.093))):
        for field, value in zip(("a2", "l2", "rws"), design, strict=True):
            tab.page.fill(f"#{prefix}-{field}", str(value))
    tab.page.fill("#duration", "0.3")
    tab.page.click("#run")
    tab.page.wait_for_selector("#series svg polyline.series", timeout=120_000)
    assert tab.page.locator("#series svg").count() == 7
    cells = tab.page.locator("#outcome tbody tr td:first-child").all_inner_texts()
    assert [c.removeprefix("■ ") for c in cells] == [label_a, label_b]
    assert tab.page.locator("#series svg text.legend").all_text_contents()[:2] == [label_a, label_b]
    for k in range(7):
        text = hover(tab, f"#series .chart-box:nth-child({k + 1}) svg")
        assert label_a in text and label_b in text, text
    assert_nothing_ran(tab, dialogs)


@pytest.mark.parametrize("payload", NAMES, ids=list(PAYLOADS))
def test_design_page_with_a_payload_in_every_query_field(tab: Page, payload: str) -> None:
    dialogs = watched(tab)
    fields = ("road", "a", "b", "label_a", "label_b", "duration")
    tab.goto("/design?" + urlencode(dict.fromkeys(fields, payload)) + "#" + payload)
    tab.ready()
    tab.page.wait_for_selector("#form-error:not(:empty), .field-error")  # the API refused the request: text
    assert tab.page.input_value("#road") == payload and tab.page.input_value("#a-label") == payload
    assert_nothing_ran(tab, dialogs)


def test_jobs_and_job_pages_show_uploaded_road_names_as_text(tab: Page, server: Server) -> None:
    specs = []
    for k, name in enumerate(NAMES):
        points = [[0, 0], [1, 0.001 * (k + 1)], [60, 0]]  # distinct points: a profile per name
        r = server.client.post("/v1/roads", json={"name": name, "points": points})
        assert r.status_code in (200, 201), r.text
        specs.append(r.json()["spec"])
    job = server.client.post("/v1/jobs", json={"kind": "sweep", "roads": specs[:2], "settings": {"duration": 0.3},
                                               "grid": "a2_deg=0:270:90,l2_m=0.04:0.08:0.04,rws_m=0.093"})
    assert job.status_code == 201, job.text
    job_id = job.json()["id"]
    # finished first: this test is of the names, not of live updates (test_dashboard has those)
    assert wait_done(server.client, job_id, timeout=300, poll=0.2)["state"] == "succeeded"
    dialogs = watched(tab)
    tab.goto("/")
    tab.ready()
    profiles = tab.page.inner_text("#profiles")
    assert all(name in profiles for name in NAMES), profiles
    tab.page.wait_for_selector(f'tr[data-job="{job_id}"] .state.succeeded', timeout=30_000)
    assert_nothing_ran(tab, dialogs)

    tab.goto(f"/jobs/{job_id}?" + urlencode({"name": NAMES[0]}) + "#" + NAMES[1])
    tab.ready()
    roads = [r["name"] for r in server.client.get(f"/v1/jobs/{job_id}").json()["roads"]]
    for road in roads:
        tab.page.select_option("#road", road)
        tab.page.wait_for_function("(road) => document.getElementById('points-note').textContent.endsWith(road)",
                                   arg=road)
        best = tab.page.evaluate("window.fdMap.best")
        x, y = tab.page.evaluate(f"window.fdMap.positionOf({best})")
        assert "distance" in hover(tab, "#map canvas", (x, y))
        tab.page.locator("#map canvas").click(position={"x": x, "y": y})
        link = tab.page.get_attribute("#open-design", "href")
        assert link is not None and link.startswith("/design?road=profile%3A"), link
        tab.page.hover("#evaluations tbody tr:first-child")
    assert tab.page.inner_text("#summary dd[data-key=roads]") == ", ".join(roads)
    assert_nothing_ran(tab, dialogs)
