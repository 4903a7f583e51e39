"""Conformance challenges (spec §17.8): the challenges the registry issued, with their secret seed and
answers, and the judged answer of each (at most one: a challenge cannot be answered twice). Both
append-only, like the records of r0001.

Revision ID: r0002
Revises: r0001
"""

import sqlalchemy as sa
from alembic import op

from haptify_tools.registry.migrations.append_only import add_triggers, drop_triggers

revision = "r0002"
down_revision = "r0001"
branch_labels = None
depends_on = None

APPEND_ONLY = ("challenges", "challenge_results")


def upgrade() -> None:
    tz = sa.DateTime(timezone=True)
    op.create_table(
        "challenges",
        sa.Column("id", sa.String(32), primary_key=True),
        sa.Column("lab_id", sa.String(64), sa.ForeignKey("labs.id"), nullable=False, index=True),
        sa.Column("token_id", sa.Integer, sa.ForeignKey("tokens.id"), nullable=False),
        sa.Column("spec_version", sa.String(16), nullable=False),
        sa.Column("seed", sa.String(64), nullable=False),
        sa.Column("cases_json", sa.Text, nullable=False),
        sa.Column("created_at", tz, nullable=False),
        sa.Column("expires_at", tz, nullable=False),
    )
    op.create_table(
        "challenge_results",
        sa.Column("challenge_id", sa.String(32), sa.ForeignKey("challenges.id"), primary_key=True),
        sa.Column("implementation_name", sa.String(200), nullable=False, index=True),
        sa.Column("implementation_version", sa.String(100), nullable=False),
        sa.Column("passed", sa.Boolean, nullable=False),
        sa.Column("verdicts_json", sa.Text, nullable=False),
        sa.Column("answered_at", tz, nullable=False),
    )
    add_triggers(APPEND_ONLY)


def downgrade() -> None:
    drop_triggers(APPEND_ONLY)
    op.drop_table("challenge_results")
    op.drop_table("challenges")
