"""Object twin: a campaign's object fit, and each result's simulation with the fitted twin.

Adds to ``campaigns`` the fit's settings (``object_fit_json``; NULL: no fit), the fitted object
twin and its hash, and the fit's report; and to ``pose_results`` a nullable ``fitted_frame_id``
naming the frame simulated with the fitted twin. Rows written before this revision keep NULL:
campaigns without an object fit.

Revision ID: 0003
Revises: 0002
Create Date: 2026-11-24 10:00:00
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0003"
down_revision: str | Sequence[str] | None = "0002"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

_CAMPAIGN_COLUMNS = (
    ("object_fit_json", sa.Text()),
    ("object_twin_json", sa.Text()),
    ("object_twin_hash", sa.String(length=64)),
    ("object_fit_report_json", sa.Text()),
)


def upgrade() -> None:
    # Plain ADD COLUMN (see 0002: no batch copies of tables that others name).
    for name, kind in _CAMPAIGN_COLUMNS:
        op.add_column("campaigns", sa.Column(name, kind, nullable=True))
    # Without a foreign key: SQLite can neither add one to an existing table nor drop a column
    # that has one (downgrade) without copying the table, which ``frames`` forbids (see 0002).
    op.add_column("pose_results",
                  sa.Column("fitted_frame_id", sa.String(length=32), nullable=True))


def downgrade() -> None:
    op.drop_column("pose_results", "fitted_frame_id")
    for name, _ in reversed(_CAMPAIGN_COLUMNS):
        op.drop_column("campaigns", name)
