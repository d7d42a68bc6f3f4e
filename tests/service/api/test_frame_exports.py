"""The service's frames in the field's forms: a frame as NeXus HDF5 and as a PLY point cloud,
a campaign's frames as one NeXus file; each read with its consumer library (h5py, nexusformat,
trimesh) and checked against the frame's own ``frame.npz``; the report links them."""

from __future__ import annotations

import io
import shutil

import h5py
import numpy as np
import pytest
import trimesh
from nexusformat.nexus import nxload

from tests.service.api.conftest import AUTH, problem, start_campaign, wait_campaign


@pytest.fixture
def campaign(client):
    """A completed two-pose campaign: its id and result rows."""
    cid = start_campaign(client, [{"turntable_deg": 0.0}, {"turntable_deg": 20.0}])
    wait_campaign(client, cid, lambda s: s["state"] == "completed")
    return cid, client.get(f"/api/v1/campaigns/{cid}/results").json()


def _npz(client, frame_id: str) -> dict[str, np.ndarray]:
    res = client.get(f"/api/v1/frames/{frame_id}/arrays")
    assert res.status_code == 200
    with np.load(io.BytesIO(res.content)) as z:
        return {k: z[k] for k in z.files}


def test_a_frame_s_nexus_file_holds_its_arrays_with_units(client, campaign, tmp_path):
    _, rows = campaign
    for key in ("measured_frame_id", "simulated_frame_id"):
        fid = rows[0][key]
        links = client.get(f"/api/v1/frames/{fid}").json()["links"]
        res = client.get(links["hdf5"])
        assert res.status_code == 200 and res.headers["content-type"] == "application/x-hdf5"
        assert f"{fid}.h5" in res.headers["content-disposition"]
        (tmp_path / f"{key}.h5").write_bytes(res.content)
        npz = _npz(client, fid)
        with h5py.File(tmp_path / f"{key}.h5", "r") as h5:
            np.testing.assert_array_equal(h5["entry/depth/data"][()], npz["depth_z_m"])
            np.testing.assert_array_equal(h5["entry/grey/data"][()], npz["grey_8bit"])
            assert h5["entry/metadata/frame_id"][()].decode() == fid
        root = nxload(str(tmp_path / f"{key}.h5"))
        assert str(root.entry.range.nxsignal.attrs["units"]) == "m"
        np.testing.assert_array_equal(root.entry.range.nxsignal.nxvalue, npz["range_m"])


def test_a_frame_s_points_read_with_trimesh_in_the_camera_and_world_frames(client, campaign):
    _, rows = campaign
    sim = rows[1]["simulated_frame_id"]
    npz = _npz(client, sim)
    n_valid = int((npz["valid"] & np.isfinite(npz["range_m"])).sum())
    for frame in ("camera", "world"):
        res = client.get(f"/api/v1/frames/{sim}/points.ply", params={"frame": frame})
        assert res.status_code == 200
        cloud = trimesh.load(io.BytesIO(res.content), file_type="ply")
        assert len(cloud.vertices) == n_valid
        props = cloud.metadata["_ply_raw"]["vertex"]["data"]
        i = n_valid // 3
        r, c = int(props["row"][i]), int(props["column"][i])
        if frame == "camera":  # z of a camera-frame point is the depth along the axis
            assert cloud.vertices[i][2] == pytest.approx(npz["depth_z_m"][r, c], abs=1e-6)
        else:  # the world point's distance to the camera centre is the range
            pose = np.asarray(client.get(f"/api/v1/frames/{sim}").json()["metadata"]
                              ["world_from_camera"])
            assert np.linalg.norm(cloud.vertices[i] - pose[:3, 3]) == pytest.approx(
                npz["range_m"][r, c], abs=1e-5)
    # a measured frame's pose is not known: the world frame is refused naming the field
    body = problem(client.get(f"/api/v1/frames/{rows[1]['measured_frame_id']}/points.ply",
                              params={"frame": "world"}), 422)
    assert "world_from_camera" in body["detail"]
    assert client.get(f"/api/v1/frames/{sim}/points.ply",
                      params={"frame": "lab"}).status_code == 422


def test_a_campaign_s_frames_are_one_nexus_file_pose_by_pose(client, campaign, tmp_path):
    cid, rows = campaign
    report = client.get(f"/api/v1/campaigns/{cid}/report").text
    assert f'href="/api/v1/campaigns/{cid}/frames.h5"' in report
    assert f'href="/api/v1/frames/{rows[0]["simulated_frame_id"]}/points.ply"' in report
    res = client.get(f"/api/v1/campaigns/{cid}/frames.h5")
    assert res.status_code == 200
    path = tmp_path / "campaign.h5"
    path.write_bytes(res.content)
    root = nxload(str(path))
    with h5py.File(path, "r") as h5:
        assert h5.attrs["campaign_id"] == cid and h5.attrs["skipped_results"].shape == (0, 2)
    for entry, key in (("measured", "measured_frame_id"), ("simulated", "simulated_frame_id")):
        depth = root[entry].depth.nxsignal
        assert depth.shape[0] == len(rows)
        assert [a.nxname for a in root[entry].depth.nxaxes] == ["frame", "y", "x"]
        for i, row in enumerate(rows):
            np.testing.assert_array_equal(depth.nxvalue[i], _npz(client, row[key])["depth_z_m"])
        np.testing.assert_array_equal(root[entry].metrics.turntable_deg.nxvalue,
                                      [r["turntable_deg"] for r in rows])
    assert "fitted" not in root
    # kept in the data directory, made again only when the results change
    kept = tmp_path / "exports" / f"{cid}.h5"
    stamp = kept.stat().st_mtime_ns
    assert client.get(f"/api/v1/campaigns/{cid}/frames.h5").content == res.content
    assert kept.stat().st_mtime_ns == stamp


def test_the_documents_point_into_the_kept_frames_file(client, campaign, tmp_path):
    cid, rows = campaign
    docs = client.get(f"/api/v1/campaigns/{cid}/documents", params={"frames": "hdf5"}).json()
    resources = [d["doc"] for d in docs if d["name"] == "stream_resource"]
    kept = tmp_path / "exports" / f"{cid}.h5"
    assert resources and {r["uri"] for r in resources} == {f"file://localhost{kept}"}
    depth = next(r for r in resources if r["data_key"] == "simulator-depth")
    datums = [d["doc"] for d in docs if d["name"] == "stream_datum"
              and d["doc"]["stream_resource"] == depth["uid"]]
    assert len(datums) == len(rows)
    with h5py.File(kept, "r") as h5:
        for datum, row in zip(datums, rows, strict=True):
            i = datum["indices"]["start"]
            np.testing.assert_array_equal(h5[depth["parameters"]["dataset"]][i],
                                          _npz(client, row["simulated_frame_id"])["depth_z_m"])
    # the default stays the ids-only form; deleting the campaign deletes its file
    plain = client.get(f"/api/v1/campaigns/{cid}/documents").json()
    assert not any(d["name"] == "stream_resource" for d in plain)
    assert client.delete(f"/api/v1/campaigns/{cid}", headers=AUTH).status_code == 204
    assert not kept.exists()


def test_a_campaign_file_leaves_out_a_pose_whose_frames_are_gone(client, campaign, tmp_path):
    cid, rows = campaign
    shutil.rmtree(tmp_path / "frames" / rows[0]["simulated_frame_id"])
    res = client.get(f"/api/v1/campaigns/{cid}/frames.h5")
    assert res.status_code == 200
    with h5py.File(io.BytesIO(res.content), "r") as h5:
        assert h5.attrs["skipped_results"].tolist() == [[rows[0]["pose_index"],
                                                         rows[0]["repeat"]]]
        assert h5["measured/depth/data"].shape[0] == h5["simulated/depth/data"].shape[0] == 1
        assert h5["measured/metrics/pose_index"][0] == rows[1]["pose_index"]
    assert problem(client.get(f"/api/v1/campaigns/{'0' * 32}/frames.h5"), 404)
