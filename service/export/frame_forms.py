"""Stored frames in the field's forms: one frame as NeXus HDF5 or as a PLY point cloud, and a
campaign's frames as one NeXus HDF5 file (docs/export-hdf5.md, docs/export-ply.md).

The layouts are :mod:`sim_core.nexus` and :mod:`sim_core.frame_points`; this module finds the
frames in the store and, for a campaign, lays them out result by result: the NXentries
``measured``, ``simulated`` (and ``fitted`` where every result has a fitted twin's frame)
hold the i-th result written at index i of their frame axis, each with the result's pose and
metrics in ``metrics``. A result whose frame folders cannot be read is left out of every entry
(its pose index and repeat are listed in the file's ``skipped_results``), so the entries stay
aligned.

A campaign's file is kept in the data directory (``exports/CAMPAIGN_ID.h5``,
:func:`campaign_frames_file`) and made again only when the campaign's results have changed,
so the file a client downloads and the file the Bluesky documents point into
(:mod:`service.export.bluesky`) are one; deleting the campaign deletes it.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import tempfile
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from sqlalchemy.orm import sessionmaker

from service.errors import GoneError
from service.export.results_table import flat_metrics, result_rows
from service.store.frame_files import FrameStore
from sim_core.frame_points import PointFrame, frame_points, ply_bytes
from sim_core.nexus import NexusFrameStack, frame_nexus_bytes

#: the entries of a campaign file: entry -> the result row's frame id key
CAMPAIGN_ENTRIES = {"measured": "measured_frame_id", "simulated": "simulated_frame_id",
                    "fitted": "fitted_frame_id"}
#: the data directory's folder of the campaigns' frames files
EXPORTS_DIR = "exports"
#: the root attribute naming the results a campaign file was made of
RESULTS_STAMP = "results_stamp"


def stored_frame_nexus(store: FrameStore, frame_id: str) -> bytes:
    """A stored frame as a NeXus HDF5 file (its bytes)."""
    return frame_nexus_bytes(store.read(frame_id))


def stored_frame_ply(store: FrameStore, frame_id: str, point_frame: PointFrame) -> bytes:
    """A stored frame's valid pixels as a PLY point cloud (its bytes) in ``point_frame``."""
    return ply_bytes(frame_points(store.read(frame_id)), point_frame)


def pose_metrics(row: dict[str, Any]) -> dict[str, Any]:
    """The numbers a campaign file keeps per result: its pose and its flat metrics."""
    return {"pose_index": row["pose_index"], "repeat": row["repeat"],
            "turntable_deg": row["turntable_deg"], "solar_suns": row["solar_suns"],
            **flat_metrics(row["metrics"])}


def results_stamp(rows: list[dict[str, Any]]) -> str:
    """A digest of the results (their ids and frame ids) a campaign file is made of."""
    digest = hashlib.sha256()
    for r in rows:
        digest.update("/".join(str(r.get(k)) for k in ("id", *CAMPAIGN_ENTRIES.values()))
                      .encode())
    return digest.hexdigest()


def write_campaign_nexus(sessions: sessionmaker, store: FrameStore, campaign_id: str,
                         path: str | Path, rows: list[dict[str, Any]] | None = None,
                         ) -> dict[str, Any]:
    """Write a campaign's results' frames into one NeXus HDF5 file at ``path`` (module
    docstring), reading one result's frames at a time. Returns ``{"results": n written,
    "skipped_results": [(pose_index, repeat), ...]}``."""
    if rows is None:
        rows = result_rows(sessions, campaign_id)  # 404 for an unknown campaign
    # the fitted twin's frames only where every result has one (a stack's entries align)
    entries = {e: k for e, k in CAMPAIGN_ENTRIES.items()
               if e != "fitted" or (rows and all(r.get(k) for r in rows))}
    skipped: list[tuple[int, int]] = []
    written = 0
    with NexusFrameStack(path) as stack:
        for row in rows:
            try:
                frames = {e: store.read(row[k]) for e, k in entries.items()}
            except GoneError:  # a lost or damaged folder: the result is left out of every entry
                skipped.append((int(row["pose_index"]), int(row["repeat"])))
                continue
            metrics = pose_metrics(row)
            for entry, frame in frames.items():
                stack.append(frame, metrics, entry=entry)
            written += 1
        stack.set_attribute("skipped_results", np.asarray(skipped, dtype=np.int64).reshape(-1, 2))
        stack.set_attribute("campaign_id", campaign_id)
        stack.set_attribute(RESULTS_STAMP, results_stamp(rows))
    return {"results": written, "skipped_results": skipped}


def campaign_frames_path(store: FrameStore, campaign_id: str) -> Path:
    """Where a campaign's frames file is kept: ``exports/CAMPAIGN_ID.h5`` beside the frames."""
    return store.root.parent / EXPORTS_DIR / f"{campaign_id}.h5"


def campaign_frames_file(sessions: sessionmaker, store: FrameStore, campaign_id: str) -> Path:
    """The campaign's frames file, made (into a temporary file beside it, then renamed) unless
    the one kept was made of the campaign's results as they are now. 404 for an unknown
    campaign."""
    rows = result_rows(sessions, campaign_id)
    path = campaign_frames_path(store, campaign_id)
    stamp = results_stamp(rows)
    with contextlib.suppress(OSError), h5py.File(path, "r") as h5:
        if h5.attrs.get(RESULTS_STAMP) == stamp:
            return path
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{campaign_id}.", suffix=".h5.tmp", dir=path.parent)
    os.close(fd)
    try:
        write_campaign_nexus(sessions, store, campaign_id, tmp, rows)
        os.replace(tmp, path)
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
    return path


def delete_campaign_frames_file(store: FrameStore, campaign_id: str) -> None:
    """Remove a campaign's kept frames file (and any temporary one of it)."""
    folder = campaign_frames_path(store, campaign_id).parent
    for p in [campaign_frames_path(store, campaign_id), *folder.glob(f".{campaign_id}.*.tmp")]:
        with contextlib.suppress(FileNotFoundError):
            p.unlink()
