"""The database: the engine (SQLite in WAL mode by default), its schema and its sessions.

The schema is made and kept up to date by Alembic migrations (:mod:`service.store.migrations`),
never by ``create_all``: :func:`init_db` upgrades the database to the newest revision.
"""

from __future__ import annotations

import os

from sqlalchemy import Engine, create_engine, event, make_url
from sqlalchemy.orm import sessionmaker

from service.store.migrations import upgrade


def make_engine(url: str) -> Engine:
    """Engine for ``url``; SQLite gets WAL, full fsync, foreign keys and a busy timeout.

    ``synchronous=FULL`` makes a commit durable against power loss as well as a killed process
    (WAL with NORMAL only survives the latter).
    """
    if not url.startswith("sqlite"):
        return create_engine(url, pool_pre_ping=True)
    _private_file(make_url(url).database)
    engine = create_engine(url, connect_args={"check_same_thread": False, "timeout": 30.0})

    @event.listens_for(engine, "connect")
    def _pragmas(dbapi_conn, _record) -> None:
        cur = dbapi_conn.cursor()
        cur.execute("PRAGMA journal_mode=WAL")
        cur.execute("PRAGMA synchronous=FULL")
        cur.execute("PRAGMA foreign_keys=ON")
        cur.execute("PRAGMA busy_timeout=30000")
        cur.close()

    return engine


def _private_file(database: str | None) -> None:
    """The SQLite file readable by its owner only (0600); its WAL and shared-memory files take
    the database file's permissions when SQLite creates them."""
    if not database or database == ":memory:" or database.startswith("file:"):
        return
    fd = os.open(database, os.O_RDWR | os.O_CREAT, 0o600)
    try:
        os.fchmod(fd, 0o600)
    finally:
        os.close(fd)


def init_db(engine: Engine) -> sessionmaker:
    """Migrate the database to the newest schema (creating it if empty); a session factory.

    A database made before migrations is checked and stamped at the first revision; one whose
    tables match no revision raises :class:`service.store.migrations.SchemaError`.
    """
    upgrade(engine)
    return sessionmaker(engine, expire_on_commit=False)
