"""``toftwin bench campaign``: poses per minute of a campaign on the simulated rig.

Each configuration (1 and 2 local workers; with ``--dask`` a ``distributed.LocalCluster`` of 1
and 2 worker processes on loopback) opens a fresh service context (database, frame store,
simulated rig, executor) in a temporary folder, runs a one-pose campaign to warm everything up
(numba kernels, worker processes), then times a campaign of ``poses`` x ``repeats`` over the
turntable. Per pose it reports the mean seconds of each stage: ``move`` (turntable and solar
simulator, instant simulators), ``capture`` (the simulated camera renders the frame),
``simulate`` (render and frame files on the worker), ``simulate_files`` (the files alone:
``save_frame`` compresses every array), ``simulate_wait`` (what the loop waited for it),
``compare``, ``store`` (frame files of both frames and the database commit).
Stages of different poses overlap when the pipeline is deeper than 1 (more than one worker),
so the stage times add up to more than the wall time per pose.
"""

from __future__ import annotations

import contextlib
import json
import os
import secrets
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from rich.console import Console

from service.cli.common import fail_invalid
from service.settings import DASK_MISSING, dask_installed
from sim_core.errors import InvalidInputError

if TYPE_CHECKING:
    from service.lab.lab import Lab


STAGES = ("move", "capture", "simulate", "simulate_files", "simulate_wait", "compare", "store")


def _run(lab: Lab, poses: int, repeats: int, spp: int, name: str):
    from service.lab.campaigns import create_campaign
    from service.lab.requests import CampaignCreate
    from service.store import queries

    angles = np.linspace(-150.0, 150.0, poses) if poses > 1 else [30.0]
    req = CampaignCreate(
        name=name, spp=spp,
        poses=[{"turntable_deg": float(a), "solar_suns": 1.0, "repeats": repeats}
               for a in angles],
    )
    cid = create_campaign(req, sessions=lab.sessions, settings=lab.settings, rig=lab.lease.rig,
                          mounted=lab.default_scene)
    t0 = time.perf_counter()
    lab.runner.start(cid)
    lab.runner.wait()
    wall = time.perf_counter() - t0
    with lab.session() as s:
        state = queries.get_campaign(s, cid).state
    if state != "completed":
        raise RuntimeError(f"benchmark campaign ended {state}")
    return wall, list(lab.runner.last_outcomes)


def bench_config(label: str, poses: int, repeats: int, spp: int, camera_spp: int,
                 rounds: int = 1, **overrides: Any) -> dict[str, Any]:
    """Time one configuration (``rounds`` campaigns, median rate); returns its figures."""
    from service.lab.lab import open_lab
    from service.settings import Settings

    walls, outcomes = [], []
    with tempfile.TemporaryDirectory(prefix="toftwin-bench-") as tmp:
        settings = Settings(token=secrets.token_urlsafe(24), data_dir=tmp, simulated=True,
                            sim_spp=spp, camera_spp=camera_spp, **overrides)
        lab = open_lab(settings)
        try:
            lab.executor.warm_up(wait=True)
            _run(lab, 1, 1, spp, "warm-up")
            for k in range(rounds):
                wall, done = _run(lab, poses, repeats, spp, f"{label} #{k}")
                walls.append(wall)
                outcomes += done
        finally:
            lab.close()
    n = len(outcomes) // rounds
    rates = [60.0 * n / w for w in walls]
    stage = {k: float(np.mean([o.timings_s.get(k, 0.0) for o in outcomes])) for k in STAGES}
    stage["store"] += float(np.mean([o.commit_s for o in outcomes]))
    return {"config": label, "executor": settings.executor, "workers": settings.workers,
            "pipeline_depth": settings.depth, "poses": n, "rounds": rounds,
            "poses_per_min": float(np.median(rates)), "poses_per_min_all": rates,
            "s_per_pose": float(np.median(walls)) / n, "stages_s": stage}


@contextlib.contextmanager
def local_cluster(n_workers: int):
    """A Dask LocalCluster of ``n_workers`` single-threaded processes on loopback."""
    from distributed import LocalCluster

    cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                           host="127.0.0.1", dashboard_address=None)
    try:
        yield cluster.scheduler_address.replace("tcp://", "dask://")
    finally:
        cluster.close()


def run_campaign_benchmark(
    poses: int, repeats: int, spp: int, camera_spp: int, workers: list[int], dask: bool,
    out: Path | None, console: Console, rounds: int = 1, local_executor: str = "local",
) -> list[dict[str, Any]]:
    """Run every configuration, print the table, optionally write JSON.

    ``local_executor`` is the executor of the "local" configurations (``thread`` in tests).
    """
    if dask and not dask_installed():  # before the local configurations, not after them
        fail_invalid(InvalidInputError("--dask", DASK_MISSING))
    results = []
    cores = os.cpu_count() or 1
    for w in workers:
        console.print(f"local executor, {w} worker(s) ...")
        results.append(bench_config(f"local x{w}", poses, repeats, spp, camera_spp, rounds,
                                    executor=local_executor, workers=w))
    if dask:
        for w in (1, 2):
            console.print(f"dask LocalCluster, {w} worker(s) ...")
            with local_cluster(w) as address:
                results.append(bench_config(
                    f"dask x{w}", poses, repeats, spp, camera_spp, rounds, executor=address,
                    workers=w, sim_threads=max(1, cores // w)))
    console.print(f"campaign benchmark: {poses} poses x {repeats}, {spp} spp simulated, "
                  f"{camera_spp} spp camera, {cores} cores, median of {rounds} round(s); "
                  "stage means in s per pose",
                  highlight=False, soft_wrap=True)
    head = f"{'config':<10}{'depth':>6}{'poses':>6}{'poses/min':>10}{'s/pose':>8}" + "".join(
        f"{k:>15}" for k in STAGES)
    console.print(head, highlight=False, soft_wrap=True)
    for r in results:
        console.print(
            f"{r['config']:<10}{r['pipeline_depth']:>6}{r['poses']:>6}"
            f"{r['poses_per_min']:>10.1f}{r['s_per_pose']:>8.3f}"
            + "".join(f"{r['stages_s'][k]:>15.3f}" for k in STAGES),
            highlight=False, soft_wrap=True)
    base = {r["config"]: r["poses_per_min"] for r in results}
    for a, b in (("local x1", "local x2"), ("dask x1", "dask x2")):
        if a in base and b in base:
            console.print(f"speed-up {b} / {a}: {base[b] / base[a]:.2f}x")
    if out is not None:
        out.write_text(json.dumps({"cores": cores, "results": results}, indent=2))
        console.print(f"wrote {out}")
    return results
