"""The service's Content-Security-Policy in a real browser (issue 25, item 7): the operator page's
screens, the API docs (Swagger UI, where the token is typed), the campaign report and a
calibration job's report all work under it, with no violation of the policy.

Every violation the browser reports (a ``securitypolicyviolation`` event, listened to from
before the page's own scripts run) is recorded, as is every console error; the policy is shown
to be in force by an inline script injected into the page, which the browser must refuse.
tests/service/api/test_security_headers.py checks the headers of every route.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tests.service.api.conftest import AUTH, TOKEN, start_campaign, wait_campaign
from tests.service.api.finished_lab import JOB_ID, done_calibration_job
from tests.web.conftest import DOC_SIZE, Page

pytestmark = pytest.mark.timeout(180)

#: listens for policy violations from before any script of the page runs (Chromium's DevTools
#: protocol adds it to every new document; it is not subject to the page's policy)
VIOLATIONS_HOOK = """
window.__cspViolations = [];
document.addEventListener("securitypolicyviolation", (e) => window.__cspViolations.push(
  [e.violatedDirective, e.blockedURI, e.sourceFile, e.lineNumber, (e.sample || "").slice(0, 80)]));
"""


@pytest.fixture(scope="module")
def csp_page(server) -> Iterator[Page]:
    """A browser window recording the policy's violations, on a service with a finished
    campaign and an active calibration from a done job."""
    cid = start_campaign(server.api, [{"turntable_deg": 10.0, "solar_suns": 1.0}],
                         name="csp")
    wait_campaign(server.api, cid, lambda s: s["state"] == "completed")
    done_calibration_job(server.app)
    res = server.api.post(f"/api/v1/calibrations/{JOB_ID}/activate", headers=AUTH)
    assert res.status_code == 200, res.text
    page = Page(server, DOC_SIZE)
    page.driver.execute_cdp_cmd("Page.addScriptToEvaluateOnNewDocument",
                                {"source": VIOLATIONS_HOOK})
    page.campaign_id = cid  # type: ignore[attr-defined]
    yield page
    page.close()


def violations(page: Page) -> list:
    return page.js("return window.__cspViolations")


def assert_policy_in_force_and_kept(page: Page, allowed: tuple[str, ...] = ()) -> None:
    """No violation so far, no console error (but ``allowed``); then an injected inline script
    is refused."""
    assert violations(page) == [], violations(page)
    page.assert_no_console_errors(allowed)
    page.js("const s = document.createElement('script'); s.textContent = 'window.__ran = 1';"
            "document.body.appendChild(s);")
    page.wait(lambda: violations(page), "the injected inline script's violation", timeout_s=5)
    assert page.js("return window.__ran") is None  # refused: the policy is in force
    assert violations(page)[0][:2] == ["script-src-elem", "inline"], violations(page)
    page.take_console()  # the refusal's own message


def test_the_operator_page_s_screens_work_under_the_policy(server, csp_page):
    page = csp_page
    page.load("rig")
    assert "SIMULATED DEVICES" in page.text("#sim-banner")
    page.enter_token()
    page.fill('#pose-form [name="turntable_deg"]', "20")
    page.fill('#pose-form [name="solar_suns"]', "1.0")
    page.click("#pose-run")  # its panels: a fragment of /ui/poses with images, Table 5
    page.wait(lambda: len(page.find_all("#pose-result .panel")) == 6, "the pose's six panels")
    assert "Depth SSIM" in page.text("#pose-result .table5")

    page.click('button[data-screen="campaigns"]')
    cid = page.campaign_id  # type: ignore[attr-defined]
    page.wait(lambda: page.find(f'#campaign-list tr[data-campaign-id="{cid}"]'), "the list")
    page.click(f'#campaign-list button[data-follow="{cid}"]')
    page.wait(lambda: page.text("#cc-latest .pose-title").startswith("Pose 1:"),
              "the campaign's latest pose")
    page.wait(lambda: page.find_all("#cc-plots img") and all(
        i.get_attribute("naturalWidth") not in (None, "0")
        for i in page.find_all("#cc-plots img")), "the campaign's plots to load")

    page.click('button[data-screen="calibration"]')
    page.wait(lambda: f"calibration job {JOB_ID}" in page.text("#calibration-active"),
              "the active calibration")
    assert_policy_in_force_and_kept(page)


def test_the_api_docs_work_under_the_policy_without_eval(server, csp_page):
    page = csp_page
    page.driver.get(f"{server.url}/api/v1/docs")
    health = page.wait(lambda: page.find("#operations-service-getHealth"),
                       "Swagger UI to list the operations", timeout_s=30.0)
    assert "getHealth" in health.text
    assert page.find("#operations-campaigns-createCampaign") is not None
    # the token is typed here: the Authorize dialog
    page.click(".auth-wrapper .authorize")
    page.fill(".modal-ux input", TOKEN)
    page.click(".modal-ux .auth-btn-wrapper .authorize")
    page.click(".modal-ux .btn-done")
    # and an operation is tried out: its answer is shown
    page.click("#operations-service-getHealth .opblock-summary")
    page.click("#operations-service-getHealth .try-out__btn")
    page.click("#operations-service-getHealth .execute")
    page.wait(lambda: '"simulated": true' in page.text(
        "#operations-service-getHealth .live-responses-table"), "the health call's answer")
    assert_policy_in_force_and_kept(page)


def test_the_reports_keep_their_own_styles_under_the_policy(server, csp_page):
    page = csp_page
    cid = page.campaign_id  # type: ignore[attr-defined]
    page.driver.get(f"{server.url}/api/v1/campaigns/{cid}/report")
    page.wait(lambda: page.find(".plots svg"), "the report's plots")
    # its own inline <style> applies (report.css: images 300 px wide)
    assert page.js("return getComputedStyle(document.querySelector('.frame-image')).width") \
        == "300px"
    assert violations(page) == [], violations(page)
    page.driver.get(f"{server.url}/api/v1/calibrations/{JOB_ID}/files/report.html")
    page.wait(lambda: "calibration report" in page.text("body"), "the calibration report")
    assert violations(page) == [], violations(page)
    # the calibration report names no icon: the browser asks for /favicon.ico (a 404)
    assert_policy_in_force_and_kept(page, allowed=("favicon.ico",))
