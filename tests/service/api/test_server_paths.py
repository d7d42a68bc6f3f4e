"""No server paths in any response, and a calibration job's files served without following a
link (issue 25, item 8).

Every GET route (walked from the app, its parameters filled with a finished campaign, pose,
frame and calibration job), the answers of the calls that made them and the 410 problems of
files gone from the data directory are searched for the data directory's absolute path and the
installation's (where the bundled scenes live): a client learns ids, file names and URLs, never
where the server keeps them.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

import service
from service.api.app import create_app
from tests.service.api.conftest import AUTH, make_settings, problem
from tests.service.api.finished_lab import (
    JOB_FILES,
    VERDICTS,
    done_calibration_job,
    finished_lab,
    get_urls,
)

pytestmark = pytest.mark.timeout(120)
#: the installation's folder (the repository in a development install: examples/, service/)
INSTALL_DIR = Path(service.__file__).resolve().parents[1]


def server_paths(data_dir: Path) -> list[bytes]:
    """The absolute paths a response must not contain, as bytes (binary responses too)."""
    paths = {str(data_dir), str(data_dir.resolve()), str(INSTALL_DIR)}
    return [p.encode() for p in paths]


def assert_no_server_path(res, needles: list[bytes], where: str) -> None:
    body = res.content
    found = [n.decode() for n in needles if n in body]
    assert not found, f"{where}: {found} in {body[:2000]!r}"
    for name, value in res.headers.items():
        assert not any(n.decode() in value for n in needles), (where, name, value)


@pytest.fixture
def lab(tmp_path):
    data = tmp_path / "server-data-dir"
    with TestClient(create_app(make_settings(data))) as client:
        yield client, finished_lab(client), data


def test_no_response_of_any_get_route_names_a_server_path(lab):
    client, finished, data = lab
    needles = server_paths(data)
    assert (data / "calibrations" / finished.job_id).is_dir()  # the path is a real one
    urls = get_urls(client.app, finished)
    urls |= {f"file {n}": f"/api/v1/calibrations/{finished.job_id}/files/{n}" for n in JOB_FILES}
    urls |= {"csv": f"/api/v1/campaigns/{finished.campaign_id}/results?format=csv"}
    for name, url in urls.items():
        res = client.get(url, follow_redirects=False)
        assert res.status_code in (200, 307), (name, url, res.status_code)
        assert_no_server_path(res, needles, f"{name} {url}")
    for res in finished.answers:  # the calls that made them: simulate, capture, pose, activate
        assert_no_server_path(res, needles, f"{res.request.method} {res.request.url}")
    # the job's status names its files by their URLs
    status = client.get(f"/api/v1/calibrations/{finished.job_id}").json()
    assert status["files"] == {n: f"/api/v1/calibrations/{finished.job_id}/files/{n}"
                               for n in JOB_FILES}
    # and gives its verdicts, as its verdicts.json holds them
    assert status["verdicts"] == VERDICTS.to_json()
    assert client.get(status["files"]["verdicts.json"]).json() == VERDICTS.to_json()


def test_files_gone_from_the_data_directory_are_named_without_server_paths(lab):
    client, finished, data = lab
    needles = server_paths(data)
    fid = finished.frame_id
    (data / "frames" / fid / "grey.png").unlink()
    body = problem(client.get(f"/api/v1/frames/{fid}/preview/grey.png"), 410)
    assert fid in body["detail"] and "grey.png" in body["detail"], body
    shutil.rmtree(data / "frames" / fid)
    gone = [client.get(f"/api/v1/frames/{fid}/arrays"),
            client.get(f"/api/v1/frames/{fid}/raw")]
    page = client.get(f"/ui/poses/{finished.pose_id}")  # the page shows the gap
    assert page.status_code == 200 and fid in page.text, page.text[:2000]
    assert_no_server_path(page, needles, "the pose's fragment")
    shutil.rmtree(finished.job_dir)
    gone += [client.get(f"/api/v1/calibrations/{finished.job_id}/files/report.html"),
             client.post(f"/api/v1/calibrations/{finished.job_id}/activate", headers=AUTH)]
    for res in gone:
        body = problem(res, 410)
        assert fid in body["detail"] or finished.job_id in body["detail"], body
        assert_no_server_path(res, needles, f"{res.request.method} {res.request.url}")


@pytest.mark.parametrize("name", JOB_FILES)
def test_a_job_file_that_is_a_link_is_not_followed(tmp_path, name):
    data = tmp_path / "server-data-dir"
    secret = tmp_path / "outside-the-data-dir.txt"
    secret.write_text("SECRET: a file the service must never serve")
    with TestClient(create_app(make_settings(data))) as client:
        out = done_calibration_job(client.app)
        (out / name).unlink()
        (out / name).symlink_to(secret)
        res = client.get(f"/api/v1/calibrations/{'d' * 32}/files/{name}")
        body = problem(res, 404)
        assert "SECRET" not in res.text and name in body["detail"], body
        assert "link" in body["detail"], body
        if name == "verdicts.json":  # the status reads it: not through a link either
            status = client.get(f"/api/v1/calibrations/{'d' * 32}").json()
            assert status["verdicts"] is None and "SECRET" not in json.dumps(status)
        if name == "calibration.yaml":  # activating would read it: refused the same way
            res = client.post(f"/api/v1/calibrations/{'d' * 32}/activate", headers=AUTH)
            assert "link" in problem(res, 404)["detail"]


def test_a_job_folder_that_is_a_link_is_not_followed(tmp_path):
    data = tmp_path / "server-data-dir"
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "report.json").write_text('{"SECRET": 1}')
    with TestClient(create_app(make_settings(data))) as client:
        out = done_calibration_job(client.app)
        shutil.rmtree(out)
        out.symlink_to(elsewhere, target_is_directory=True)
        res = client.get(f"/api/v1/calibrations/{'d' * 32}/files/report.json")
        body = problem(res, 404)
        assert "SECRET" not in res.text and "link" in body["detail"], body
