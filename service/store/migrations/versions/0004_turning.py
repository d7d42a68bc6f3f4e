"""Capture while turning (issue 27): a campaign's turning speed.

Adds to ``campaigns`` a nullable ``turning_deg_s`` (NULL: stop and go, as every campaign written
before this revision).

Revision ID: 0004
Revises: 0003
Create Date: 2026-11-27 15:00:00
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0004"
down_revision: str | Sequence[str] | None = "0003"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    # Plain ADD COLUMN (see 0002: no batch copies of tables that others name).
    op.add_column("campaigns", sa.Column("turning_deg_s", sa.Float(), nullable=True))


def downgrade() -> None:
    op.drop_column("campaigns", "turning_deg_s")
