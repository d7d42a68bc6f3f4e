"""A really full disk (a small tmpfs filled to its last byte): writes answer 507 naming what was
being written and leave nothing behind, deletes work, and the service starts and serves reads.

Mounting a tmpfs needs root (CAP_SYS_ADMIN): these tests carry the ``root`` mark, which the
default run leaves out; CI runs them as root (``.ci/run``). Without the rights to mount, the
fixture fails saying so. The free-space floor's own tests (the settings' value, no mount) are
in test_disk_space.py.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from service.store.disk_space import free_bytes
from tests.service.api.conftest import AUTH, problem, start_campaign, wait_campaign

pytestmark = pytest.mark.root
#: the small disk's size: the database, a few tiny frames and the 16 MiB reserve
DISK_BYTES = 64 * 1024 * 1024


@pytest.fixture
def small_disk(tmp_path: Path) -> Iterator[Path]:
    """A tmpfs of :data:`DISK_BYTES` at ``tmp_path/disk``, unmounted at the end (lazily: the
    service's files may still be open while it stops)."""
    mnt = tmp_path / "disk"
    mnt.mkdir()
    res = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={DISK_BYTES},mode=0700",
                          "tmpfs", str(mnt)], capture_output=True, text=True)
    if res.returncode != 0:
        pytest.fail(f"these tests mount a small tmpfs and need root (CAP_SYS_ADMIN): "
                    f"{res.stderr.strip()}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


def fill(disk: Path, name: str = "filler") -> None:
    """Fill ``disk`` to its last byte (a file of zeros, unbuffered, until ENOSPC)."""
    with open(disk / name, "ab", buffering=0) as fh:
        for chunk in (1 << 20, 4096, 1):
            try:
                while True:
                    fh.write(b"\0" * chunk)
            except OSError as exc:
                assert exc.errno == 28, exc
    assert free_bytes(disk) == 0


def frame_folders(data: Path) -> list[str]:
    return sorted(p.name for p in (data / "frames").iterdir())


def test_a_full_disk_is_a_507_naming_what_was_written_and_nothing_is_left(
    small_disk, make_client
):
    data = small_disk / "data"
    client = make_client(data, min_free_bytes=0)  # no floor: the write itself finds it full
    assert client.post("/api/v1/poses", headers=AUTH,
                       json={"turntable_deg": 0.0, "solar_suns": 1.0}).status_code == 201
    before = frame_folders(data)
    fill(small_disk)
    for route, body, what in (
        ("/api/v1/poses", {"turntable_deg": 10.0, "solar_suns": 1.0},
         "the pose's measured frame"),
        ("/api/v1/devices/camera/capture", None, "the captured frame"),
        ("/api/v1/simulate", {"scene": "satellite_ground_test"}, "the simulated frame"),
    ):
        detail = problem(client.post(route, headers=AUTH, json=body), 507)["detail"]
        assert f"writing {what} failed" in detail, detail
        assert "0 B free" in detail and "TOFTWIN_MIN_FREE_BYTES=0" in detail, detail
        assert str(small_disk) not in detail
        assert frame_folders(data) == before, route  # no frame, no partial folder
    assert len(client.get("/api/v1/frames").json()) == len(before)


def test_deleting_a_campaign_or_a_frame_works_on_a_full_disk(small_disk, make_client):
    data = small_disk / "data"
    client = make_client(data, min_free_bytes=0)
    cids = []
    for angle in (0.0, 20.0):
        cids.append(start_campaign(client, [{"turntable_deg": angle}]))
        wait_campaign(client, cids[-1], lambda s: s["state"] == "completed")
    frames = [client.post("/api/v1/devices/camera/capture", headers=AUTH).json()["frame_id"]
              for _ in range(2)]
    fill(small_disk)
    # with the reserve the service keeps: the rows go first, then the folders
    assert client.delete(f"/api/v1/frames/{frames[0]}", headers=AUTH).status_code == 204
    assert client.delete(f"/api/v1/campaigns/{cids[0]}", headers=AUTH).status_code == 204
    assert problem(client.get(f"/api/v1/campaigns/{cids[0]}"), 404)
    # without it (the disk filled up after the reserve went): the folders first, then the rows
    (data / ".space-reserve").unlink(missing_ok=True)
    fill(small_disk, "filler2")
    assert client.delete(f"/api/v1/campaigns/{cids[1]}", headers=AUTH).status_code == 204
    assert client.delete(f"/api/v1/frames/{frames[1]}", headers=AUTH).status_code == 204
    assert client.get("/api/v1/frames").json() == []
    assert frame_folders(data) == []


def test_the_service_starts_on_a_full_disk_serves_reads_and_refuses_writes(
    small_disk, make_client
):
    data = small_disk / "data"
    first = make_client(data, min_free_bytes=0)
    cid = start_campaign(first, [{"turntable_deg": 0.0}])
    wait_campaign(first, cid, lambda s: s["state"] == "completed")
    first.__exit__(None, None, None)
    fill(small_disk)

    # it starts (no traceback, no refusal): the reserve the first start kept gives SQLite the
    # room to open its log, and stays given back while the disk is full
    client = make_client(data, min_free_bytes=10**9)
    assert client.get("/api/v1/health").json()["status"] == "ok"
    assert client.get(f"/api/v1/campaigns/{cid}").json()["state"] == "completed"
    assert client.get(f"/api/v1/campaigns/{cid}/report").status_code == 200
    assert len(client.get("/api/v1/frames").json()) == 2
    res = client.post("/api/v1/poses", headers=AUTH, json={"turntable_deg": 5.0, "solar_suns": 1.0})
    assert "below the 953.7 MiB kept free" in problem(res, 507)["detail"]
    assert free_bytes(small_disk) < 16 * 2**20
    assert os.path.getsize(data / ".lock") == 0  # held, its description had no room
    assert client.delete(f"/api/v1/campaigns/{cid}", headers=AUTH).status_code == 204


def test_without_its_reserve_the_service_refuses_to_start_on_a_full_disk_in_a_sentence(
    small_disk, make_client
):
    """The reserve gone (a delete on the full disk released it), SQLite has no room to open its
    log: ``toftwin serve`` says so with the sizes and exits 2, no traceback, nothing written."""
    data = small_disk / "data"
    first = make_client(data, min_free_bytes=0)
    first.__exit__(None, None, None)
    (data / ".space-reserve").unlink()
    fill(small_disk)
    before = sorted(p.name for p in data.iterdir())
    res = subprocess.run([sys.executable, "-m", "toftwin_cli", "serve", "--simulated",
                          "--data-dir", str(data), "--port", "9"],
                         capture_output=True, text=True, timeout=120,
                         env={**os.environ, "TOFTWIN_TOKEN": "t" * 24})
    assert res.returncode == 2, res
    assert "disk is full: 0 B free" in res.stderr and "1.0 MiB" in res.stderr, res.stderr
    assert "Traceback" not in res.stderr + res.stdout
    assert sorted(p.name for p in data.iterdir()) == before
