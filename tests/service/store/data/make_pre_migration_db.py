"""Make ``pre_migration.db``: a database as the service wrote it before schema migrations.

Run once, from the repository root, at commit 85cb308 (the last commit whose ``init_db`` was
``Base.metadata.create_all``)::

    python -m tests.service.store.data.make_pre_migration_db \
        tests/service/store/data/pre_migration.db

It goes through the service's own writes (:mod:`service.store.queries`) on a database made by
that ``init_db``: two campaigns (one completed, one paused half-way) with their planned poses,
four campaign results and one ad-hoc pose result with their frame rows, and one stand-alone
capture. Times and ids are fixed so the file is reproducible. The file is switched out of WAL
mode and vacuumed so that it is one small file. Do not regenerate it with later code: it stands
for the databases that exist in the field, made by the old schema.
"""

from __future__ import annotations

import sqlite3
import sys
from pathlib import Path
from unittest import mock

from service.store import queries
from service.store.database import init_db, make_engine

SCENE = '{"name": "tiny", "objects": []}'


def make(path: Path) -> None:
    if path.exists():
        raise SystemExit(f"{path} exists; remove it first")
    engine = make_engine(f"sqlite:///{path}")
    sessions = init_db(engine)
    clock = iter(1_760_000_000.0 + 0.25 * k for k in range(1000))
    with mock.patch.object(queries, "now", lambda: next(clock)), sessions() as s:
        # campaign A: two poses (the second repeated twice), all done, completed
        queries.create_campaign(
            s, campaign_id="a" * 32, name="turntable sweep", scene_name="tiny", scene_json=SCENE,
            scene_base_dir="/srv/scenes", mask={"kind": "valid"}, seed=5, spp=4,
            poses=[(0.0, 0.0, 1), (45.0, 0.5, 2)],
        )
        queries.transition(s, "a" * 32, ("created",), "running", started=True, count_run=True)
        for pose, repeat, angle, suns, k in ((0, 0, 0.0, 0.0, 1), (1, 0, 45.0, 0.5, 2),
                                             (1, 1, 45.0, 0.5, 3)):
            add(s, "a" * 32, pose, repeat, angle, suns, k)
        queries.transition(s, "a" * 32, ("running",), "completed", finished=True)

        # campaign B: three poses, one done, paused
        queries.create_campaign(
            s, campaign_id="b" * 32, name="sun ramp", scene_name="tiny", scene_json=SCENE,
            scene_base_dir="/srv/scenes", mask={}, seed=7, spp=1,
            poses=[(10.0, 0.0, 1), (10.0, 1.0, 1), (-30.5, 1.5, 3)],
        )
        queries.transition(s, "b" * 32, ("created",), "running", started=True, count_run=True)
        add(s, "b" * 32, 0, 0, 10.0, 0.0, 4)
        queries.transition(s, "b" * 32, ("running",), "paused")

        # an ad-hoc pose comparison (no campaign) and a stand-alone capture
        add(s, None, 0, 0, 90.0, 0.25, 5)
        queries.add_frame(s, queries.frame_row(
            "f" * 32, "measured", scene_name="tiny", scene_hash="c" * 64,
            rig={"turntable_deg": 12.5, "solar_suns": 0.0}, summary={"valid_fraction": 0.5},
        ))
    engine.dispose()
    con = sqlite3.connect(path)
    con.execute("PRAGMA journal_mode=DELETE")
    con.execute("VACUUM")
    con.close()


def add(s, campaign_id, pose, repeat, angle, suns, k) -> None:
    """A result and its two frame rows (ids and figures derived from ``k``)."""
    rig = {"turntable_deg": angle, "solar_suns": suns, "exposure_s": 0.001}
    frames = [
        queries.frame_row(f"{k:x}{'d' if kind == 'measured' else 'e'}".ljust(32, "0"), kind,
                          campaign_id=campaign_id,
                          scene_name="tiny", scene_hash=f"{k}".rjust(64, "0"), rig=rig,
                          summary={"valid_fraction": 0.9 - 0.1 * k, "kind": kind})
        for kind in ("measured", "simulated")
    ]
    queries.add_result(
        s, campaign_id=campaign_id, pose_index=pose, repeat=repeat, turntable_deg=angle,
        solar_suns=suns, measured=frames[0], simulated=frames[1],
        metrics={"range_rmse_m": 0.01 * k, "bias_m": float("nan") if k == 3 else -0.002 * k},
        rig=rig, timings_s={"rig": 0.5 * k, "simulate": 1.25, "compare": 0.03},
    )


if __name__ == "__main__":
    make(Path(sys.argv[1]))
