"""Recordings (issue 28): a campaign that records what it captures, or replays a recording.

Adds to ``campaigns`` two nullable columns: ``record_path`` (the HDF5 recording the campaign
writes its captured frames to; NULL: it records nothing) and ``replay_path`` (the recording it
replays instead of capturing; NULL: it captures on the rig, as every campaign written before
this revision).

Revision ID: 0005
Revises: 0004
Create Date: 2026-11-29 03:00:00
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0005"
down_revision: str | Sequence[str] | None = "0004"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    # Plain ADD COLUMN (see 0002: no batch copies of tables that others name).
    op.add_column("campaigns", sa.Column("record_path", sa.Text(), nullable=True))
    op.add_column("campaigns", sa.Column("replay_path", sa.Text(), nullable=True))


def downgrade() -> None:
    op.drop_column("campaigns", "replay_path")
    op.drop_column("campaigns", "record_path")
