"""Every HTML page comes from the one Jinja2 environment factory (``sim_core.html``): the
operator page and its fragments, the API docs, the campaign report and the calibration's
``report.html``. What a user typed (a campaign's name, a calibration's provenance) is shown as
text on each of them."""

from __future__ import annotations

import re
from pathlib import Path

import jinja2

from calibration.report import write_report
from calibration.rig_sequence import RigCalibration
from calibration.verdicts import Verdict, Verdicts, read_verdicts
from service.api.routes import api_docs, page
from service.web import SHARED_TEMPLATES, STATIC_DIR, TEMPLATE_FOLDERS, environment
from sim_core.html import jinja_environment, number
from sim_core.twin_file import parse_calibration
from tests.service.api.conftest import AUTH
from tests.service.api.test_calibration import CALIBRATION

REPO = Path(__file__).parents[3]
PACKAGES = ("sim_core", "drivers", "calibration", "service", "benchmarks", "toftwin_cli")
SCRIPT = "<script>alert(1)</script>"
ESCAPED = "&lt;script&gt;alert(1)&lt;/script&gt;"


def shown_as_text(html: str) -> bool:
    return ESCAPED in html and SCRIPT not in html


def test_no_module_but_the_factory_makes_a_jinja_environment():
    makers = {str(path.relative_to(REPO)) for package in PACKAGES
              for path in (REPO / package).rglob("*.py")
              if re.search(r"\bEnvironment\(|Jinja2Templates\((?!env=environment\(\))",
                           path.read_text(encoding="utf-8"))}
    assert makers == {"sim_core/html.py"}


def test_the_page_the_api_docs_and_both_reports_share_the_factory_s_rules():
    web = jinja_environment("service.web", TEMPLATE_FOLDERS, SHARED_TEMPLATES)
    assert environment() is web and page.templates.env is web and api_docs.templates.env is web
    for env in (web, jinja_environment("calibration")):
        assert env.autoescape is True and env.undefined is jinja2.StrictUndefined
        assert env.filters["number"] is number and env.trim_blocks and env.lstrip_blocks


def test_a_campaign_named_like_a_script_is_text_in_the_list_and_the_report(client):
    res = client.post("/api/v1/campaigns", headers=AUTH,
                      json={"name": SCRIPT, "poses": [{"turntable_deg": 0.0}]})
    assert res.status_code == 201, res.text
    cid = res.json()["id"]
    assert shown_as_text(client.get("/ui/campaigns").text)
    report = client.get(f"/api/v1/campaigns/{cid}/report")
    assert report.status_code == 200 and shown_as_text(report.text)


def test_a_calibration_s_provenance_is_text_on_the_page_and_in_its_report(client, tmp_path):
    data = {**CALIBRATION, "provenance": {
        **CALIBRATION["provenance"], "rig": SCRIPT, "created_utc": SCRIPT,
        "procedures": {SCRIPT: {"rms_px": 0.1}, "intrinsics": {"rejected": [
            {"name": SCRIPT, "reason": SCRIPT}]}}}}
    res = client.put("/api/v1/calibration", headers=AUTH, json=data)
    assert res.status_code == 200, res.text
    assert shown_as_text(client.get("/ui/calibration").text)
    verdicts = Verdicts({"camera.fx_px": Verdict("unexplained", 0.4, SCRIPT),
                         "turntable.axis_point_m": Verdict("determined", [1e-4, 2e-4, 0.0])})
    outcome = RigCalibration(calibration=parse_calibration(data), results={}, views=[],
                             frames_used=12, verdicts=verdicts)
    paths = write_report(tmp_path / "out", outcome)
    html = paths["html"].read_text(encoding="utf-8")
    assert shown_as_text(html)
    assert f"<h1>Calibration of {ESCAPED}</h1>" in html
    assert f"<tr><td>{ESCAPED}</td><td>{ESCAPED}</td></tr>" in html  # a view not used, and why
    # every key's verdict, its reason as text, beside the file in verdicts.json
    assert "2 keys: 1 determined, 0 not determined, 1 unexplained" in html
    # the one verdict table (calibration/templates/_verdicts.html), as the page shows it
    assert ('<tr class="unexplained"><td class="what">camera.fx_px</td>\n      '
            f'<td>unexplained</td><td class="num">0.4</td>\n      '
            f'<td class="what">{ESCAPED}</td></tr>') in html
    assert '<td class="num">0.0001, 0.0002, 0</td>' in html
    assert read_verdicts(paths["verdicts"]) == verdicts
    # and the camera in OpenCV's form (issue 29)
    import cv2

    fs = cv2.FileStorage(str(paths["opencv"]), cv2.FILE_STORAGE_READ)
    assert fs.getNode("camera_matrix").mat()[0, 0] == CALIBRATION["camera"]["fx_px"]
    fs.release()


def test_a_pose_s_figures_look_the_same_on_the_page_and_in_the_report(client):
    figures_css = (STATIC_DIR / "figures.css").read_text()
    assert ".tof-figures" in figures_css
    page = client.get("/")
    assert '<link rel="stylesheet" href="/static/figures.css">' in page.text
    assert client.get("/static/figures.css").text == figures_css
    cid = client.post("/api/v1/campaigns", headers=AUTH,
                      json={"name": "css", "poses": [{"turntable_deg": 0.0}]}).json()["id"]
    report = client.get(f"/api/v1/campaigns/{cid}/report").text
    assert figures_css.strip() in report  # one self-contained file: the rules inlined, not linked
    assert "/static/" not in report
