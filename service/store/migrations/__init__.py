"""Schema migrations (Alembic), run by :func:`upgrade` when the service opens its database.

The scripts are in ``versions/``; ``env.py`` and ``script.py.mako`` are Alembic's environment
and revision template. No ``alembic.ini`` is needed at run time: :func:`alembic_config` builds
the configuration in code, pointing at this package's folder (the repository's ``alembic.ini``
is only for the ``alembic`` command line; see docs/service.md, "Schema migrations").

Databases written before migrations existed (``Base.metadata.create_all``, no
``alembic_version`` table) are recognised by their tables, checked against the schema of the
first revision (:data:`BASELINE_SCHEMA`) and stamped at :data:`BASELINE`, never re-created.
"""

from __future__ import annotations

from pathlib import Path

from alembic import command
from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy import Connection, Engine, inspect

#: the folder holding env.py, script.py.mako and versions/
SCRIPT_LOCATION = Path(__file__).resolve().parent
#: the first revision: the schema of the service before migrations
BASELINE = "0001"

#: table -> (columns, index names, unique column lists) as ``create_all`` made them before
#: migrations; frozen here, independent of :mod:`service.store.tables`, which moves on.
BASELINE_SCHEMA: dict[str, tuple[frozenset[str], frozenset[str], frozenset[tuple[str, ...]]]] = {
    "campaigns": (
        frozenset({"id", "name", "scene_name", "scene_json", "scene_base_dir", "mask_json",
                   "seed", "spp", "state", "error", "poses_total", "runs", "created_at",
                   "started_at", "updated_at", "finished_at"}),
        frozenset({"ix_campaigns_state"}),
        frozenset(),
    ),
    "campaign_poses": (
        frozenset({"id", "campaign_id", "pose_index", "turntable_deg", "solar_suns", "repeats"}),
        frozenset({"ix_campaign_poses_campaign_id"}),
        frozenset({("campaign_id", "pose_index")}),
    ),
    "frames": (
        frozenset({"id", "kind", "campaign_id", "scene_name", "scene_hash", "rig_json",
                   "summary_json", "created_at"}),
        frozenset({"ix_frames_campaign_id"}),
        frozenset(),
    ),
    "pose_results": (
        frozenset({"id", "campaign_id", "pose_index", "repeat", "turntable_deg", "solar_suns",
                   "measured_frame_id", "simulated_frame_id", "metrics_json", "rig_json",
                   "timings_json", "created_at"}),
        frozenset({"ix_pose_results_campaign_id"}),
        frozenset({("campaign_id", "pose_index", "repeat")}),
    ),
}


class SchemaError(RuntimeError):
    """The database holds service tables that match no known revision; nothing was changed."""


def alembic_config(url: str | None = None) -> Config:
    """An Alembic configuration for this package's scripts (``url`` for the command API)."""
    cfg = Config()
    cfg.set_main_option("script_location", str(SCRIPT_LOCATION))
    if url is not None:
        cfg.set_main_option("sqlalchemy.url", url.replace("%", "%%"))
    return cfg


def head_revision() -> str:
    """The newest revision of the scripts."""
    head = ScriptDirectory.from_config(alembic_config()).get_current_head()
    assert head is not None
    return head


def current_revision(engine: Engine) -> str | None:
    """The revision the database is at (None: not under migrations)."""
    with engine.connect() as conn:
        return MigrationContext.configure(conn).get_current_revision()


def upgrade(engine: Engine, revision: str = "head") -> None:
    """Bring the database to ``revision``: create it, stamp a pre-migration one, migrate.

    Runs in one connection and transaction (SQLite runs DDL outside of it; a crash half-way
    leaves tables without a version row, recognised by the baseline check at the next start).
    """
    cfg = alembic_config()
    with engine.begin() as conn:
        cfg.attributes["connection"] = conn
        if _is_pre_migration(conn):
            _check_baseline(conn)
            command.stamp(cfg, BASELINE)
        command.upgrade(cfg, revision)


def downgrade(engine: Engine, revision: str) -> None:
    """Take the database back to ``revision`` (``"base"``: no tables), for tests and repairs."""
    cfg = alembic_config()
    with engine.begin() as conn:
        cfg.attributes["connection"] = conn
        command.downgrade(cfg, revision)


def _is_pre_migration(conn: Connection) -> bool:
    """Service tables but no version row: made by ``create_all`` before migrations."""
    names = set(inspect(conn).get_table_names())
    if not names & BASELINE_SCHEMA.keys():
        return False
    return MigrationContext.configure(conn).get_current_revision() is None


def _check_baseline(conn: Connection) -> None:
    """Raise :class:`SchemaError` unless the tables are those of :data:`BASELINE`."""
    insp = inspect(conn)
    names = set(insp.get_table_names())
    problems = []
    for table, (columns, indexes, uniques) in BASELINE_SCHEMA.items():
        if table not in names:
            problems.append(f"table {table} is missing")
            continue
        got_cols = {c["name"] for c in insp.get_columns(table)}
        if got_cols != columns:
            problems.append(f"{table} has columns {sorted(got_cols ^ columns)} that differ")
        got_ix = {ix["name"] for ix in insp.get_indexes(table) if not ix.get("unique")}
        if got_ix != indexes:
            problems.append(f"{table} has indexes {sorted(got_ix)}, expected {sorted(indexes)}")
        got_uq = {tuple(u["column_names"]) for u in insp.get_unique_constraints(table)}
        if got_uq != uniques:
            problems.append(f"{table} has unique constraints {sorted(got_uq)}, "
                            f"expected {sorted(uniques)}")
    if problems:
        raise SchemaError(
            "the database has the service's tables but no alembic_version, and they are not "
            f"the schema of revision {BASELINE}: " + "; ".join(problems)
        )
