"""Schema migrations: a fresh database gets head, a pre-migration one is stamped and kept whole."""

from __future__ import annotations

import shutil
import sqlite3
from pathlib import Path

import pytest
from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext
from sqlalchemy import create_engine

from service.lab.lab import open_lab
from service.store import migrations
from service.store.database import init_db, make_engine
from service.store.tables import Base
from tests.service.api.conftest import make_settings

FIXTURE = Path(__file__).parent / "data" / "pre_migration.db"
TABLES = ("campaigns", "campaign_poses", "frames", "pose_results")


def rows(path: Path) -> dict[str, list[tuple]]:
    """Every row of the service's tables, in primary-key order (read without touching WAL),
    with the columns of the first revision (later revisions add columns)."""
    con = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
    try:
        return {t: con.execute(f"SELECT {', '.join(sorted(migrations.BASELINE_SCHEMA[t][0]))} "
                               f"FROM {t} ORDER BY id").fetchall() for t in TABLES}
    finally:
        con.close()


def added_columns(path: Path) -> dict[str, list[tuple]]:
    """The calibration columns revision 0002 added, per table, in primary-key order."""
    con = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
    try:
        return {
            "campaigns": con.execute("SELECT calibration_hash, calibration_json FROM campaigns "
                                     "ORDER BY id").fetchall(),
            "frames": con.execute("SELECT calibration_hash FROM frames ORDER BY id").fetchall(),
            "pose_results": con.execute(
                "SELECT calibration_hash FROM pose_results ORDER BY id").fetchall(),
            "new_tables": con.execute(
                "SELECT (SELECT count(*) FROM calibration_activations),"
                " (SELECT count(*) FROM calibration_jobs)").fetchall(),
        }
    finally:
        con.close()


def schema(path: Path) -> set[tuple[str, str, str | None]]:
    """The tables and indexes (name, type, normalised SQL) of a SQLite file."""
    con = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
    try:
        found = con.execute(
            "SELECT type, name, sql FROM sqlite_master WHERE name != 'alembic_version'"
            " AND name NOT LIKE 'sqlite_autoindex_alembic%'").fetchall()
    finally:
        con.close()
    return {(kind, name, " ".join(sql.split()) if sql else None) for kind, name, sql in found}


@pytest.fixture
def old_db(tmp_path) -> Path:
    """A copy of the pre-migration fixture, as the data directory's database."""
    data = tmp_path / "data"
    data.mkdir()
    path = data / "toftwin.db"
    shutil.copyfile(FIXTURE, path)
    return path


def test_the_fixture_is_a_pre_migration_database():
    names = {name for _, name, _ in schema(FIXTURE)}
    assert set(TABLES) <= names
    con = sqlite3.connect(f"file:{FIXTURE}?mode=ro", uri=True)
    try:
        assert not con.execute(
            "SELECT 1 FROM sqlite_master WHERE name = 'alembic_version'").fetchall()
    finally:
        con.close()
    before = rows(FIXTURE)
    assert {t: len(r) for t, r in before.items()} == {
        "campaigns": 2, "campaign_poses": 5, "frames": 11, "pose_results": 5}


def test_a_pre_migration_database_is_stamped_and_every_row_survives(old_db):
    before = rows(old_db)
    lab = open_lab(make_settings(old_db.parent))  # the service's start-up path
    try:
        assert migrations.current_revision(lab.engine) == migrations.head_revision()
        assert lab.recovered["interrupted"] == []
        with lab.session() as s:
            from service.store import queries

            assert queries.get_campaign(s, "a" * 32).state == "completed"
            assert queries.get_campaign(s, "b" * 32).state == "paused"
            assert queries.done_units(s, "a" * 32) == {(0, 0), (1, 0), (1, 1)}
            assert [p.repeats for p in queries.planned_poses(s, "b" * 32)] == [1, 1, 3]
    finally:
        lab.close()
    assert rows(old_db) == before
    # revision 0002's columns: NULL (nominal) on every old row; its tables empty
    assert added_columns(old_db) == {"campaigns": [(None, None)] * 2, "frames": [(None,)] * 11,
                                     "pose_results": [(None,)] * 5, "new_tables": [(0, 0)]}


def test_upgrading_0001_to_0002_keeps_every_row_and_downgrading_drops_only_the_new(old_db):
    before = rows(old_db)
    engine = make_engine(f"sqlite:///{old_db}")
    try:
        migrations.upgrade(engine, migrations.BASELINE)  # stamped at 0001, unchanged
        assert migrations.current_revision(engine) == "0001"
        migrations.upgrade(engine, "0002")
        assert rows(old_db) == before
        assert added_columns(old_db)["frames"] == [(None,)] * 11
        with engine.begin() as conn:  # a calibrated result can be stored at 0002
            conn.exec_driver_sql("UPDATE frames SET calibration_hash = 'abc' WHERE rowid = 1")
        migrations.downgrade(engine, "0001")
        assert rows(old_db) == before
        assert "calibration_jobs" not in {n for _, n, _ in schema(old_db)}
    finally:
        engine.dispose()
    assert schema(old_db) == schema(FIXTURE)


def test_the_first_revision_is_exactly_the_pre_migration_schema(tmp_path):
    engine = make_engine(f"sqlite:///{tmp_path / 'new.db'}")
    migrations.upgrade(engine, migrations.BASELINE)
    engine.dispose()
    assert schema(tmp_path / "new.db") == schema(FIXTURE)


def test_a_fresh_database_gets_head_and_matches_the_tables(tmp_path):
    engine = make_engine(f"sqlite:///{tmp_path / 'fresh.db'}")
    init_db(engine)
    try:
        assert migrations.current_revision(engine) == migrations.head_revision()
        with engine.connect() as conn:
            assert compare_metadata(MigrationContext.configure(conn), Base.metadata) == []
        init_db(engine)  # a second start changes nothing
        assert migrations.current_revision(engine) == migrations.head_revision()
    finally:
        engine.dispose()


def test_downgrade_to_base_and_upgrade_again(tmp_path, old_db):
    before = rows(old_db)
    engine = make_engine(f"sqlite:///{tmp_path / 'round.db'}")
    try:
        migrations.upgrade(engine)
        created = schema(tmp_path / "round.db")
        migrations.downgrade(engine, "base")
        assert migrations.current_revision(engine) is None
        assert schema(tmp_path / "round.db") == set()
        migrations.upgrade(engine)
        assert migrations.current_revision(engine) == migrations.head_revision()
        assert schema(tmp_path / "round.db") == created
    finally:
        engine.dispose()
    # and a stamped old database goes down to its baseline and back up with its rows
    engine = make_engine(f"sqlite:///{old_db}")
    try:
        migrations.upgrade(engine)
        migrations.downgrade(engine, migrations.BASELINE)
        migrations.upgrade(engine)
        assert migrations.current_revision(engine) == migrations.head_revision()
    finally:
        engine.dispose()
    assert rows(old_db) == before


def test_tables_that_match_no_revision_are_refused_untouched(tmp_path):
    path = tmp_path / "odd.db"
    con = sqlite3.connect(path)
    con.execute("CREATE TABLE campaigns (id VARCHAR(32) PRIMARY KEY, name TEXT)")
    con.execute("INSERT INTO campaigns VALUES ('x', 'kept')")
    con.commit()
    con.close()
    engine = create_engine(f"sqlite:///{path}")
    try:
        with pytest.raises(migrations.SchemaError, match="campaigns has columns"):
            init_db(engine)
        assert migrations.current_revision(engine) is None
    finally:
        engine.dispose()
    con = sqlite3.connect(path)
    assert con.execute("SELECT * FROM campaigns").fetchall() == [("x", "kept")]
    assert [r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type='table'")] == [
        "campaigns"]
    con.close()
