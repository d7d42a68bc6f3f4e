"""Stored frames in the field's forms: one frame as NeXus HDF5 or as a PLY point cloud, and a
campaign's frames as one NeXus HDF5 file (docs/export-hdf5.md, docs/export-ply.md).

The layouts are :mod:`sim_core.nexus` and :mod:`sim_core.frame_points`; this module finds the
frames in the store and, for a campaign, lays them out pose by pose: the NXentries
``measured``, ``simulated`` (and ``fitted`` where every result has a fitted twin's frame)
hold the i-th pose result's frames at index i of their frame axis, each with the result's pose
and metrics in ``metrics``. A result whose frame folders cannot be read is left out of every
entry (its pose index is listed in the file's ``skipped_pose_indices``), so the entries stay
aligned.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

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


def stored_frame_nexus(store: FrameStore, frame_id: str) -> bytes:
    """A stored frame as a NeXus HDF5 file (its bytes)."""
    return frame_nexus_bytes(store.read(frame_id))


def stored_frame_ply(store: FrameStore, frame_id: str, point_frame: PointFrame) -> bytes:
    """A stored frame's valid pixels as a PLY point cloud (its bytes) in ``point_frame``."""
    return ply_bytes(frame_points(store.read(frame_id)), point_frame)


def pose_metrics(row: dict[str, Any]) -> dict[str, Any]:
    """The numbers a campaign file keeps per pose: the result's pose and its flat metrics."""
    return {"pose_index": row["pose_index"], "repeat": row["repeat"],
            "turntable_deg": row["turntable_deg"], "solar_suns": row["solar_suns"],
            **flat_metrics(row["metrics"])}


def write_campaign_nexus(sessions: sessionmaker, store: FrameStore, campaign_id: str,
                         path: str | Path) -> dict[str, Any]:
    """Write a campaign's pose results' frames into one NeXus HDF5 file at ``path`` (module
    docstring). Returns ``{"results": n written, "skipped_pose_indices": [...]}``."""
    rows = result_rows(sessions, campaign_id)  # 404 for an unknown campaign
    # the fitted twin's frames only where every result has one (a stack's entries align)
    entries = {e: k for e, k in CAMPAIGN_ENTRIES.items()
               if e != "fitted" or (rows and all(r.get(k) for r in rows))}
    skipped: list[int] = []
    written = 0
    with NexusFrameStack(path) as stack:
        for row in rows:
            try:
                frames = {e: store.read(row[k]) for e, k in entries.items()}
            except GoneError:  # a lost or damaged folder: the pose is left out of every entry
                skipped.append(int(row["pose_index"]))
                continue
            metrics = pose_metrics(row)
            for entry, frame in frames.items():
                stack.append(frame, metrics, entry=entry)
            written += 1
        stack.set_attribute("skipped_pose_indices", np.asarray(skipped, dtype=np.int64))
        stack.set_attribute("campaign_id", campaign_id)
    return {"results": written, "skipped_pose_indices": skipped}

