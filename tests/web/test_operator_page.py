"""The operator page in a real headless Chromium against the real app on the simulated rig:
loading, a manual pose, a campaign from the form followed live (paused and resumed on the way),
the emergency stop during a move, the API's messages next to the form's fields, the token."""

from __future__ import annotations

import time

import pytest

from service.export.plots import CAMPAIGN_PLOTS
from tests.service.api.conftest import AUTH, problem, start_campaign, wait_campaign
from tests.service.api.finished_lab import VERDICTS, done_calibration_job
from tests.web.conftest import DOC_SIZE, SIZES

pytestmark = pytest.mark.timeout(300)


def assert_images_keep_their_aspect_ratio(page, css: str, count: int) -> None:
    """Each image is loaded and shown at its own aspect ratio (within a pixel of rounding)."""
    sizes = page.wait(lambda: (lambda s: s if len(s) == count and all(
        x[0] > 0 and x[4] for x in s) else None)(page.js(
        "return Array.from(document.querySelectorAll(arguments[0])).map(i => [i.naturalWidth,"
        " i.naturalHeight, i.getBoundingClientRect().width, i.getBoundingClientRect().height,"
        " i.complete])", css)), f"{count} images {css} to load")
    for natural_w, natural_h, shown_w, shown_h, complete in sizes:
        assert complete and shown_w > 0
        assert shown_h == pytest.approx(shown_w * natural_h / natural_w, abs=1.0), sizes


def fill_campaign_form(page, name: str, angles: str, suns: str = "1.0",
                       repeats: str = "1") -> None:
    """A fresh page's campaign screen, the token entered, the form filled and submitted."""
    page.load("campaigns")
    page.enter_token()
    page.fill("#cf-name", name)
    page.fill("#cf-angles", angles)
    page.fill("#cf-suns", suns)
    page.fill("#cf-repeats", repeats)
    page.click("#campaign-create")


def wait_for_latest_pose(page) -> None:
    """The latest pose's images are those of the last pose done (they load after the status)."""
    done = int(page.text("#cc-progress").split(" / ")[0])
    page.wait(lambda: page.text("#cc-latest .pose-title").startswith(f"Pose {done}:"),
              f"pose {done}'s images")
    assert_images_keep_their_aspect_ratio(page, "#cc-latest .frame-image", 6)
    assert_images_keep_their_aspect_ratio(page, "#cc-latest .colour-bar", 6)


@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
def test_the_page_loads_on_the_simulated_rig_and_runs_a_manual_pose(server, page_at, size):
    page = page_at(server, size)
    page.take_console()
    page.load("rig")
    assert "SIMULATED DEVICES" in page.text("#sim-banner")
    assert page.find("#estop").is_displayed()
    devices = {d.get_attribute("data-device") for d in page.find_all("#devices .device")}
    assert devices == {"turntable", "solar_simulator", "camera"}
    assert "deg" in page.text('[data-device="turntable"] .angle')
    assert page.text("#token-state") in ("read-only", "token kept for this session")
    page.shot("rig", doc=True)

    page.enter_token()
    page.fill('#pose-form [name="turntable_deg"]', "20")
    page.fill('#pose-form [name="solar_suns"]', "1.0")
    page.click("#pose-run")
    page.wait(lambda: len(page.find_all("#pose-result .panel")) == 6, "the pose's six panels")
    captions = [f.text for f in page.find_all("#pose-result .panel figcaption")]
    assert captions[:2] == ["grey measured", "grey simulated"]
    assert "depth measured" in captions and "depth simulated" in captions
    assert_images_keep_their_aspect_ratio(page, "#pose-result .frame-image", 6)
    assert_images_keep_their_aspect_ratio(page, "#pose-result .colour-bar", 6)
    bars = [b.get_attribute("title") for b in page.find_all("#pose-result .colour-bar")]
    assert "range [m]" in bars and "range sim - meas [mm]" in bars, bars
    table = page.text("#pose-result .table5")
    for row in ("Grey Mean", "Depth SSIM", "Depth PSNR"):
        assert row in table, table
    # the depth difference and the pixel shares come first, above Table 5
    assert "median [mm]" in page.text("#pose-result .tof-depth")
    assert "flying" in page.text("#pose-result .tof-pixels")
    assert page.js("return document.querySelector('#pose-result .tof-depth')"
                   ".compareDocumentPosition(document.querySelector('#pose-result .table5'))"
                   " & Node.DOCUMENT_POSITION_FOLLOWING") != 0
    assert "grey [DN], 1st-99th pct of valid pixels" in bars, bars
    # the panels are the pose the API stored
    pose_id = int(page.find("#pose-result .pose").get_attribute("data-pose-id"))
    stored = server.api.get(f"/api/v1/poses/{pose_id}").json()
    assert stored["turntable_deg"] == 20.0
    # the grey shown is the pose's stretched panel, not the frame's stored (dark) grey.png
    assert page.find('#pose-result [data-panel="grey-measured"] img').get_attribute(
        "src").endswith(f"/api/v1/poses/{pose_id}/panels/grey-measured.png")
    page.js("window.scrollTo(0, document.querySelector('#pose-form').offsetTop - 60)")
    page.shot("pose", doc=True)
    page.assert_no_console_errors()


def test_a_campaign_from_the_form_runs_live_and_pauses_and_resumes(server, page):
    fill_campaign_form(page, "three poses", "-30, 0, 30")
    page.js("window.notReloaded = true")
    page.wait(lambda: page.text("#cc-state") == "created", "the campaign to be created")
    assert page.text("#cc-progress") == "0 / 3 poses"
    assert not page.find("#cc-pause").is_enabled() and page.find("#cc-start").is_enabled()

    # every progress the page shows, as it shows it
    page.js("window.progressSeen = [document.querySelector('#cc-progress').textContent];"
            "new MutationObserver(() => window.progressSeen.push(document.querySelector("
            "'#cc-progress').textContent)).observe(document.querySelector('#cc-progress'),"
            " {childList: true, characterData: true, subtree: true})")
    page.click("#cc-start")
    page.wait(lambda: page.text("#cc-state") == "running", "the campaign to run")
    assert page.find("#cc-pause").is_enabled() and not page.find("#cc-start").is_enabled()
    # Paused while the first pose is being worked on: the pause lands after the poses in
    # flight (one here), so at least one is done, and not all (the next one starts only after
    # the first is done, and the page's request takes far less than a pose).
    page.wait(lambda: page.text("#cc-pose").startswith("now: pose 1:"),
              "the first pose to be worked on")
    page.click("#cc-pause")
    page.wait(lambda: page.text("#cc-state") == "paused", "the campaign to pause")
    done = int(page.text("#cc-progress").split(" / ")[0])
    assert 1 <= done < 3
    assert page.find("#cc-resume").is_enabled() and not page.find("#cc-pause").is_enabled()
    wait_for_latest_pose(page)
    page.shot("campaign-paused", doc=True)

    page.click("#cc-resume")
    page.wait(lambda: page.text("#cc-progress") == "3 / 3 poses", "the progress to reach 3 / 3")
    page.wait(lambda: page.text("#cc-state") == "completed", "the campaign to complete")
    assert page.js("return window.notReloaded") is True  # followed live, never reloaded
    shown = [int(t.split(" / ")[0]) for t in page.js("return window.progressSeen") if t]
    assert shown[0] == 0 and shown[-1] == 3 and done in shown, shown
    assert shown == sorted(shown), shown  # never backwards
    assert all(not page.find(b).is_enabled() for b in ("#cc-start", "#cc-pause", "#cc-resume",
                                                       "#cc-cancel"))
    # the latest pair is the last pose's, the list has the campaign with its links
    page.wait(lambda: page.text("#cc-latest .pose-title") == "Pose 3: 30 deg, 1 sun",
              "the last pose's images")
    cid = server.api.get("/api/v1/campaigns").json()[0]["id"]
    status = server.api.get(f"/api/v1/campaigns/{cid}").json()
    assert status["state"] == "completed" and status["runs"] == 2
    # the list follows the campaign's events too: under load its last update may come later
    row = page.wait(lambda: (r := page.find(f'#campaign-list tr[data-campaign-id="{cid}"]'))
                    and "3 / 3" in r.text and "completed" in r.text and r,
                    "the campaign in the list, completed")
    links = {a.text: a.get_attribute("href") for a in row.find_elements("css selector", "a")}
    assert links["report"].endswith(f"/api/v1/campaigns/{cid}/report")
    assert server.api.get(links["CSV"]).text.count("\n") == 4  # header and three rows


def test_a_finished_campaign_opened_from_the_list_shows_its_pair_plots_and_report(server, page):
    cid = start_campaign(server.api, [{"turntable_deg": a, "solar_suns": 1.0}
                                      for a in (-20, 10, 40)], name="finished")
    wait_campaign(server.api, cid, lambda s: s["state"] != "running")
    page.load("campaigns")
    row = page.wait(lambda: page.find(f'#campaign-list tr[data-campaign-id="{cid}"]'),
                    "the campaign in the list")
    assert "completed" in row.text and "3 / 3" in row.text
    page.click(f'#campaign-list button[data-follow="{cid}"]')
    # the latest pair, the plots (with the three poses), as the page shows them at the end
    page.wait(lambda: page.text("#cc-latest .pose-title") == "Pose 3: 40 deg, 1 sun",
              "the last pose's images")
    assert page.text("#cc-state") == "completed" and page.text("#cc-progress") == "3 / 3 poses"
    assert_images_keep_their_aspect_ratio(page, "#cc-latest .frame-image", 6)
    assert_images_keep_their_aspect_ratio(page, "#cc-plots img", len(CAMPAIGN_PLOTS))
    page.js("document.querySelector('#cc-live').scrollIntoView()")
    page.shot("campaign-live", doc=True)
    page.js("document.querySelector('#campaign-list').scrollIntoView({block: 'end'})")
    page.shot("campaign", doc=True)

    # its report: the same panels with colour bars, the plots (matplotlib SVG), self-contained
    report = page.find(f'#campaign-list tr[data-campaign-id="{cid}"] a[href$="/report"]')
    assert report.text == "report"
    page.driver.get(report.get_attribute("href"))
    assert_images_keep_their_aspect_ratio(page, ".frame-image", 3 * 6)
    assert_images_keep_their_aspect_ratio(page, ".colour-bar", 3 * 6)
    assert len(page.find_all(".plots svg")) == len(CAMPAIGN_PLOTS)
    assert all(i.get_attribute("src").startswith("data:image/png;base64,")
               for i in page.find_all("img"))
    page.shot("report", doc=True)


def test_the_emergency_stop_stops_a_running_move(moving_server, page_at):
    server = moving_server
    page = page_at(server, DOC_SIZE)
    page.take_console()
    page.load("rig")
    page.enter_token()
    start = server.api.get("/api/v1/devices/turntable/position").json()["angle_deg"]
    target = 150.0 if start < 60 else -150.0
    page.fill("#move-angle", f"{target:g}")
    page.click("#move-btn")
    page.wait(lambda: abs(server.api.get("/api/v1/devices/turntable/position").json()[
        "angle_deg"] - start) > 5.0, "the turntable to move")
    page.click("#estop")
    page.wait(lambda: "Stopped: turntable, shutter" in page.text("#message"), "the stop's report")
    time.sleep(1.0)
    first = server.api.get("/api/v1/devices/turntable/position").json()["angle_deg"]
    time.sleep(0.5)
    second = server.api.get("/api/v1/devices/turntable/position").json()["angle_deg"]
    assert second == pytest.approx(first, abs=0.01)  # it stays where it stopped
    assert abs(second - target) > 20.0  # well short of the target
    assert server.api.get("/api/v1/devices/solar").json()["shutter_open"] is False
    page.wait(lambda: f"{second:.2f} deg" in page.text('[data-device="turntable"] .angle'),
              "the rig panel to show where it stopped")
    page.shot("emergency-stop", doc=True)
    page.assert_no_console_errors(allowed=("503",))


def test_a_device_that_does_not_answer_is_shown_with_its_error_and_the_fix(server, page):
    faults = server.rig.sims["turntable"].servers["turntable"].faults
    page.load("rig")
    faults.inject("no-reply")  # the controller goes deaf
    try:
        card = page.wait(lambda: page.find('#devices .device.bad[data-device="turntable"]'),
                         "the turntable's card to turn red")
        assert "DeviceTimeoutError" in card.text and "check its cable and power" in card.text
        page.shot("device-error", doc=True)
    finally:
        faults.clear()
    page.wait(lambda: page.find('#devices .device.ok[data-device="turntable"]'),
              "the turntable back to normal")


def test_a_bad_form_value_shows_the_apis_message_next_to_the_field(server, page):
    fill_campaign_form(page, "bad angle", "0, 400", repeats="0")
    angle = page.wait(lambda: page.text('#campaign-form .field-error[data-field="turntable_deg"]'),
                      "the angle's message")
    repeats = page.text('#campaign-form .field-error[data-field="repeats"]')
    # exactly what the API answers to the same request, each next to its own field
    api = server.post("/api/v1/campaigns", {"name": "bad angle", "poses": [
        {"turntable_deg": 0, "solar_suns": 1, "repeats": 0},
        {"turntable_deg": 400, "solar_suns": 1, "repeats": 0}]})
    by_field = {e["field"]: e["message"] for e in problem(api, 422)["errors"]}
    assert f"poses[1].turntable_deg: {by_field['poses[1].turntable_deg']}" in angle
    assert "allowed: -360 to 360 deg" in angle
    assert f"poses[0].repeats: {by_field['poses[0].repeats']}" in repeats
    assert page.text('#campaign-form .field-error[data-field="name"]') == ""
    assert page.find("#campaign-current").is_displayed() is False  # nothing was created
    page.shot("form-error", doc=True)
    page.assert_no_console_errors(allowed=("422",))


def test_reading_needs_no_token_and_commands_say_they_need_it(server, page_at):
    # a campaign of its own (created, not started), whichever tests ran on this server before
    created = server.post("/api/v1/campaigns", {"name": "read without a token", "poses": [
        {"turntable_deg": 0, "solar_suns": 1}]})
    assert created.status_code == 201, created.text
    cid = created.json()["id"]
    page = page_at(server, DOC_SIZE)
    page.load("rig")
    page.js("sessionStorage.clear()")
    page.load("campaigns")
    assert page.text("#token-state") == "read-only"
    page.wait(lambda: page.find(f'#campaign-list tr[data-campaign-id="{cid}"]'),
              "the campaign in the list")
    page.load("rig")
    page.fill("#move-angle", "10")
    page.click("#move-btn")
    page.wait(lambda: "needs the token" in page.text("#message"), "the token message")
    page.assert_no_console_errors(allowed=("401",))


@pytest.mark.slow
def test_a_paused_campaign_says_why_and_resumes_from_its_explanation(server, page):
    fill_campaign_form(page, "stopped on the way", "-40:20:20")  # a range: -40, -20, 0, 20
    page.wait(lambda: page.text("#cc-progress") == "0 / 4 poses", "the 4-pose campaign")
    page.click("#cc-start")
    page.wait(lambda: page.text("#cc-state") == "running", "the campaign to run")
    page.click("#estop")
    page.wait(lambda: page.text("#cc-state") == "paused", "the campaign to pause")
    why = page.wait(lambda: page.find("#cc-why:not([hidden])"), "the explanation")
    assert "Paused: emergency stop" in why.text and "resume" in why.text.lower()
    page.shot("campaign-why", doc=True)
    page.click("#cc-why .why-resume")
    page.wait(lambda: page.text("#cc-state") == "completed", "the campaign to complete")
    assert page.text("#cc-progress") == "4 / 4 poses"
    assert page.find("#cc-why").is_displayed() is False
    cid = server.api.get("/api/v1/campaigns").json()[0]["id"]
    rows = server.api.get(f"/api/v1/campaigns/{cid}/results").json()
    assert [r["turntable_deg"] for r in rows] == [-40, -20, 0, 20]


@pytest.mark.slow
def test_a_campaign_paused_by_a_stalled_turntable_offers_to_enable_it_and_resume(server, page):
    fill_campaign_form(page, "stall on the way", "-60, -20, 20, 60")
    page.wait(lambda: page.text("#cc-progress") == "0 / 4 poses", "the 4-pose campaign")
    # the third move of the campaign stalls (a following error) and leaves the controller
    # disabled: the campaign pauses after two poses
    server.rig.sims["turntable"].servers["turntable"].faults.inject("stall:1@2")
    page.click("#cc-start")
    page.wait(lambda: page.text("#cc-state") == "paused", "the campaign to pause")
    assert page.text("#cc-progress") == "2 / 4 poses"
    why = page.wait(lambda: page.find("#cc-why:not([hidden])"), "the explanation")
    assert "Paused:" in why.text and "turntable" in why.text.lower()
    buttons = {b.text: b for b in why.find_elements("css selector", "button")}
    assert {"Enable the turntable", "Resume"} <= set(buttons), buttons
    wait_for_latest_pose(page)
    page.shot("campaign-fault", doc=True)

    buttons["Enable the turntable"].click()
    page.wait(lambda: "READY" in {d["name"]: d for d in server.api.get("/api/v1/devices").json()[
        "devices"]}["turntable"]["details"]["status"], "the turntable to be enabled")
    page.click("#cc-why .why-resume")
    page.wait(lambda: page.text("#cc-state") == "completed", "the campaign to complete")
    assert page.text("#cc-progress") == "4 / 4 poses"
    page.assert_no_console_errors(allowed=("503",))  # the rig panel may meet the fault too


def test_the_calibration_screen_shows_the_active_calibration_and_its_residuals(server, page):
    cal = {"provenance": {"created_utc": "2026-11-24T09:30:00Z", "rig": "lab-1",
                          "procedures": {"intrinsics": {"rms_px": 0.21},
                                         "depth": {"rms_after_mm": 1.8}}}}
    assert server.api.put("/api/v1/calibration", headers=AUTH, json=cal).status_code == 200
    page.load("calibration")
    page.wait(lambda: page.find("#calibration-active .residuals"), "the residuals")
    text = page.text("#calibration-active")
    assert "2026-11-24T09:30:00Z" in text and "rms_px" in text and "0.21" in text
    assert "rms_after_mm" in text and "1.8" in text
    assert page.find("#calibration-start").is_displayed()
    page.shot("calibration", doc=True)


def test_a_calibration_job_started_from_the_page_is_followed_to_its_end(server, page):
    # At the test service's 1 sample per pixel the camera's frames are too noisy for the board
    # detector: the job runs its captures, then fails saying why and what to do.
    page.load("calibration")
    page.enter_token()
    page.click("#calibration-form input[name=warmup_stage]")  # the camera counted warm
    page.click("#calibration-start")
    page.wait(lambda: page.find("#calibration-job").is_displayed(), "the job's progress")
    page.wait(lambda: page.text("#cj-state") == "failed", "the job to end")
    plan = server.api.get("/api/v1/calibrations").json()[0]["plan"]
    assert plan["warmup_stage"] is False and plan["settling_stage"] is True, plan
    assert "steps)" in page.text("#cj-message")
    error = page.text("#cj-error")
    job = server.api.get("/api/v1/calibrations").json()[0]
    assert job["state"] == "failed" and error == job["error"]
    assert "board was detected" in error and "start a new job" in error
    assert not page.find("#cj-cancel").is_enabled()
    page.shot("calibration-job", doc=True)


def test_a_done_calibration_job_shows_every_key_s_verdict_as_text(server, page):
    done_calibration_job(server.app, job_id="e" * 32)
    page.load("calibration")
    page.wait(lambda: page.find("#cj-verdicts").is_displayed(), "the job's verdicts")
    assert page.text("#cj-state") == "done"
    # the calibration report's table (one macro), rendered by the service
    assert page.text("#cj-verdicts .verdict-counts") == ("2 keys: 1 determined, 1 not "
                                                         "determined, 0 unexplained")
    rows = page.find_all("#cj-verdicts tbody tr")
    cells = [[td.text for td in r.find_elements("css selector", "td")] for r in rows]
    assert cells == [
        ["camera.fx_px", "determined", "0.05", ""],
        ["turntable.axis_point_m", "not determined", "0.003, 0.0001, 0",
         VERDICTS["turntable.axis_point_m"].reason],  # its markup shown as text
    ]
    assert rows[1].get_attribute("class") == "not-determined"
    assert not page.find_all("#cj-verdicts b")
    assert "verdicts.json" in page.text("#cj-links")
    page.assert_no_console_errors()
