"""Registry-wide re-verification (spec §17.9): the runs and, per run and submission, the re-computed
values beside the submission's own record. Both append-only, like the records of r0001.

Revision ID: r0004
Revises: r0003
"""

import sqlalchemy as sa

from haptify_tools.registry.migrations.append_only import create_tables, drop_tables

revision, down_revision, branch_labels, depends_on = "r0004", "r0003", None, None
TABLES = ("reverify_runs", "reverify_records")


def upgrade() -> None:
    tz = sa.DateTime(timezone=True)
    create_tables(
        {
            "reverify_runs": [
                sa.Column("id", sa.String(32), primary_key=True),
                sa.Column("reference_version", sa.String(50), nullable=False, index=True),
                sa.Column("spec_version", sa.String(16), nullable=False),
                sa.Column("since_version", sa.String(50)),
                sa.Column("executor", sa.String(300), nullable=False),
                sa.Column("planned_json", sa.Text, nullable=False),
                sa.Column("created_at", tz, nullable=False),
            ],
            "reverify_records": [
                sa.Column("submission_id", sa.String(32), sa.ForeignKey("submissions.id"), primary_key=True),
                sa.Column("reference_version", sa.String(50), primary_key=True),
                sa.Column("run_id", sa.String(32), sa.ForeignKey("reverify_runs.id"), primary_key=True, index=True),
                sa.Column("status", sa.String(16), nullable=False, index=True),
                sa.Column("verification", sa.String(16)),
                sa.Column("previous_verification", sa.String(16), nullable=False),
                sa.Column("checks_json", sa.Text, nullable=False),
                sa.Column("findings_json", sa.Text, nullable=False),
                sa.Column("worker", sa.String(300), nullable=False),
                sa.Column("seconds", sa.Float, nullable=False),
                sa.Column("recorded_at", tz, nullable=False),
            ],
        }
    )


def downgrade() -> None:
    drop_tables(TABLES)
