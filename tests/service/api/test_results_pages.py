"""Results come a page at a time; CSV and Bluesky documents stream every row."""

from __future__ import annotations

import csv
import io

from fastapi.testclient import TestClient

from service.api.app import create_app
from tests.service.api.conftest import make_settings
from tests.service.api.test_sse_load import _big_campaign


def test_results_are_paged_and_csv_and_documents_hold_every_row(tmp_path):
    data = tmp_path / "data"
    cid = _big_campaign(data, poses=25, repeats=100)  # 2500 results
    with TestClient(create_app(make_settings(data))) as client:
        base = f"/api/v1/campaigns/{cid}/results"
        first = client.get(base)
        assert first.status_code == 200
        assert len(first.json()) == 1000 and first.headers["X-Total-Count"] == "2500"
        assert first.headers["Link"] == f'<{base}?limit=1000&offset=1000>; rel="next"'
        seen, url = [], base
        while url:
            page = client.get(url)
            seen += [(r["pose_index"], r["repeat"]) for r in page.json()]
            link = page.headers.get("Link")
            url = link[1:link.index(">")] if link else None
        assert seen == [(p, r) for p in range(25) for r in range(100)]
        last = client.get(base, params={"limit": 300, "offset": 2400})
        assert len(last.json()) == 100 and "Link" not in last.headers

        table = list(csv.DictReader(io.StringIO(client.get(base, params={"format": "csv"}).text)))
        assert len(table) == 2500 and table[-1]["pose_index"] == "24"

        docs = client.get(f"/api/v1/campaigns/{cid}/documents").json()
        assert [d["name"] for d in docs[:2]] == ["start", "descriptor"]
        assert sum(d["name"] == "event" for d in docs) == 2500
        assert [d["doc"]["seq_num"] for d in docs if d["name"] == "event"][-1] == 2500

        assert client.get(f"{base}?limit=0").status_code == 422
        missing = "0" * 32
        for path in (f"/api/v1/campaigns/{missing}/results?format=csv",
                     f"/api/v1/campaigns/{missing}/documents"):
            assert client.get(path).status_code == 404
