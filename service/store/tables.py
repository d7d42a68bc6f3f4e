"""The service's tables.

``campaigns`` and their planned ``campaign_poses``; ``pose_results`` (one row per pose and repeat
of a campaign, or one per ad-hoc pose comparison), each naming its two ``frames``. Frame pixels
live in files under the data directory (:mod:`service.store.frame_files`); a ``frames`` row is
written in the same transaction as the result that uses it, so a frame without a row is an
orphan of a crash.

``UNIQUE(campaign_id, pose_index, repeat)`` makes a repeated result impossible, not just unlikely.

Calibration (revision 0002): ``calibration_activations`` is the history of the service's active
calibration (the newest row is the active one; a row without content means "nominal"), and
``calibration_jobs`` are the calibration sequences run on the rig. Frames, results and campaigns
record the calibration hash (:func:`sim_core.twin_file.twin_hash`) they used; a campaign keeps
the calibration it pinned when it was created, so a resume applies the same one.

Object twin (revision 0003): a campaign with an object fit stores the fit's settings, the fitted
object twin and its report; each of its results names a third frame, the simulation with the
fitted twin.
Times are seconds since the epoch (floats), as in Bluesky documents. Every change to these
classes comes with a migration (:mod:`service.store.migrations`).
"""

from __future__ import annotations

from sqlalchemy import Boolean, Float, ForeignKey, Integer, String, Text, UniqueConstraint
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column


class Base(DeclarativeBase):
    """Declarative base of the service's tables."""


class CampaignRow(Base):
    """A campaign: a scene, a list of poses, and where it stands."""

    __tablename__ = "campaigns"

    id: Mapped[str] = mapped_column(String(32), primary_key=True)
    name: Mapped[str] = mapped_column(String(200))
    scene_name: Mapped[str] = mapped_column(String(200))
    scene_json: Mapped[str] = mapped_column(Text)
    scene_base_dir: Mapped[str] = mapped_column(Text)
    mask_json: Mapped[str] = mapped_column(Text)
    seed: Mapped[int] = mapped_column(Integer)
    spp: Mapped[int] = mapped_column(Integer)
    state: Mapped[str] = mapped_column(String(16), index=True)
    error: Mapped[str | None] = mapped_column(Text, nullable=True)
    poses_total: Mapped[int] = mapped_column(Integer)
    runs: Mapped[int] = mapped_column(Integer, default=0)
    created_at: Mapped[float] = mapped_column(Float)
    started_at: Mapped[float | None] = mapped_column(Float, nullable=True)
    updated_at: Mapped[float] = mapped_column(Float)
    finished_at: Mapped[float | None] = mapped_column(Float, nullable=True)
    #: the calibration pinned at creation (its JSON and hash; None: nominal)
    calibration_hash: Mapped[str | None] = mapped_column(String(64), nullable=True)
    calibration_json: Mapped[str | None] = mapped_column(Text, nullable=True)
    #: the object fit's settings (:class:`~service.lab.requests.ObjectFitIn`; None: no fit)
    object_fit_json: Mapped[str | None] = mapped_column(Text, nullable=True)
    #: the fitted object twin (``ObjectTwinFile`` as JSON) and its hash, once fitted
    object_twin_json: Mapped[str | None] = mapped_column(Text, nullable=True)
    object_twin_hash: Mapped[str | None] = mapped_column(String(64), nullable=True)
    #: the fit's report (residuals, uncertainties, what was not determined)
    object_fit_report_json: Mapped[str | None] = mapped_column(Text, nullable=True)
    #: capture while turning at this speed [deg/s] (None: stop and go)
    turning_deg_s: Mapped[float | None] = mapped_column(Float, nullable=True)
    #: the recording the campaign writes its captures to (:mod:`service.store.recording`;
    #: None: it records nothing)
    record_path: Mapped[str | None] = mapped_column(Text, nullable=True)
    #: the recording the campaign replays instead of capturing (None: it captures on the rig)
    replay_path: Mapped[str | None] = mapped_column(Text, nullable=True)


class PlannedPoseRow(Base):
    """One pose of a campaign as planned: rig state and number of repeats."""

    __tablename__ = "campaign_poses"
    __table_args__ = (UniqueConstraint("campaign_id", "pose_index"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    campaign_id: Mapped[str] = mapped_column(ForeignKey("campaigns.id"), index=True)
    pose_index: Mapped[int] = mapped_column(Integer)
    turntable_deg: Mapped[float] = mapped_column(Float)
    solar_suns: Mapped[float] = mapped_column(Float)
    repeats: Mapped[int] = mapped_column(Integer)


class FrameRow(Base):
    """A measured or simulated frame; its files are in ``<data_dir>/frames/<id>/``."""

    __tablename__ = "frames"

    id: Mapped[str] = mapped_column(String(32), primary_key=True)
    kind: Mapped[str] = mapped_column(String(16))
    campaign_id: Mapped[str | None] = mapped_column(String(32), nullable=True, index=True)
    scene_name: Mapped[str] = mapped_column(String(200), default="")
    scene_hash: Mapped[str] = mapped_column(String(64), default="")
    rig_json: Mapped[str] = mapped_column(Text, default="null")
    summary_json: Mapped[str] = mapped_column(Text, default="{}")
    created_at: Mapped[float] = mapped_column(Float)
    #: the calibration the simulation applied (a measured frame: whose intrinsics reconstructed
    #: it); None: nominal
    calibration_hash: Mapped[str | None] = mapped_column(String(64), nullable=True)


class PoseResultRow(Base):
    """The comparison of one measured and one simulated frame (a pose and repeat).

    ``metrics_json`` is the comparison as one JSON document (``ComparisonReport.to_dict()`` with
    the Table 5 text rows under ``table``, and ``explained`` for campaigns with an object fit),
    so a figure added to the report needs no schema change: the depth difference and pixel
    shares (``tof``) came that way, and rows stored before them simply lack the key.
    """

    __tablename__ = "pose_results"
    __table_args__ = (UniqueConstraint("campaign_id", "pose_index", "repeat"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    campaign_id: Mapped[str | None] = mapped_column(
        ForeignKey("campaigns.id"), nullable=True, index=True
    )
    pose_index: Mapped[int] = mapped_column(Integer)
    repeat: Mapped[int] = mapped_column(Integer)
    turntable_deg: Mapped[float] = mapped_column(Float)
    solar_suns: Mapped[float] = mapped_column(Float)
    measured_frame_id: Mapped[str] = mapped_column(ForeignKey("frames.id"))
    simulated_frame_id: Mapped[str] = mapped_column(ForeignKey("frames.id"))
    metrics_json: Mapped[str] = mapped_column(Text)
    rig_json: Mapped[str] = mapped_column(Text)
    timings_json: Mapped[str] = mapped_column(Text)
    created_at: Mapped[float] = mapped_column(Float)
    #: the calibration the simulation applied; None: nominal
    calibration_hash: Mapped[str | None] = mapped_column(String(64), nullable=True)
    #: the simulation with the fitted object twin (campaigns with an object fit; else None).
    #: No foreign key: SQLite cannot add or drop one on an existing table without copying it
    #: (see revision 0003); the frame row is committed in the same transaction as the result.
    fitted_frame_id: Mapped[str | None] = mapped_column(String(32), nullable=True)


class CalibrationActivationRow(Base):
    """One change of the active calibration; the newest row (highest id) is in force."""

    __tablename__ = "calibration_activations"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    #: the calibration file's content as JSON; None: back to nominal
    calibration_json: Mapped[str | None] = mapped_column(Text, nullable=True)
    calibration_hash: Mapped[str | None] = mapped_column(String(64), nullable=True)
    #: where it came from: ``PUT /calibration``, ``calibration job <id>``, ``DELETE /calibration``
    source: Mapped[str] = mapped_column(String(200))
    activated_at: Mapped[float] = mapped_column(Float)


class CalibrationJobRow(Base):
    """A calibration sequence run on the rig as a background job."""

    __tablename__ = "calibration_jobs"

    id: Mapped[str] = mapped_column(String(32), primary_key=True)
    state: Mapped[str] = mapped_column(String(16), index=True)
    plan_json: Mapped[str] = mapped_column(Text)
    activate: Mapped[bool] = mapped_column(Boolean, default=False)
    steps_done: Mapped[int] = mapped_column(Integer, default=0)
    steps_total: Mapped[int] = mapped_column(Integer, default=0)
    message: Mapped[str] = mapped_column(Text, default="")
    error: Mapped[str | None] = mapped_column(Text, nullable=True)
    out_dir: Mapped[str] = mapped_column(Text)
    calibration_hash: Mapped[str | None] = mapped_column(String(64), nullable=True)
    activated: Mapped[bool] = mapped_column(Boolean, default=False)
    created_at: Mapped[float] = mapped_column(Float)
    started_at: Mapped[float | None] = mapped_column(Float, nullable=True)
    updated_at: Mapped[float] = mapped_column(Float)
    finished_at: Mapped[float | None] = mapped_column(Float, nullable=True)
