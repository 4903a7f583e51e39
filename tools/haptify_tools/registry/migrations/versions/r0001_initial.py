"""The registry's first schema: labs, tokens, devices, submissions, metric values, withdrawals,
conformance reports on file; the
append-only rule as triggers (spec §17.5).

Revision ID: r0001
Revises:
"""

import sqlalchemy as sa
from alembic import op

from haptify_tools.registry.migrations.append_only import add_triggers, drop_triggers

revision = "r0001"
down_revision = None
branch_labels = None
depends_on = None

APPEND_ONLY = ("submissions", "metric_values", "withdrawals", "conformance_reports")


def upgrade() -> None:
    tz = sa.DateTime(timezone=True)
    op.create_table(
        "labs",
        sa.Column("id", sa.String(64), primary_key=True),
        sa.Column("name", sa.String(200)),
        sa.Column("created_at", tz, nullable=False),
    )
    op.create_table(
        "tokens",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("lab_id", sa.String(64), sa.ForeignKey("labs.id"), nullable=False, index=True),
        sa.Column("scope", sa.String(16), nullable=False),
        sa.Column("token_sha256", sa.String(64), nullable=False, unique=True),
        sa.Column("rate_per_minute", sa.Integer, nullable=False),
        sa.Column("created_at", tz, nullable=False),
    )
    op.create_table(
        "devices",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("slug", sa.String(200), nullable=False, unique=True),
        sa.Column("manufacturer", sa.String(200), nullable=False),
        sa.Column("model", sa.String(200), nullable=False),
        sa.UniqueConstraint("manufacturer", "model", name="uq_devices_manufacturer_model"),
    )
    op.create_table(
        "submissions",
        sa.Column("id", sa.String(32), primary_key=True),
        sa.Column("digest", sa.String(64), nullable=False, unique=True),
        sa.Column("archive_sha256", sa.String(64), nullable=False),
        sa.Column("archive_size", sa.Integer, nullable=False),
        sa.Column("archive_path", sa.String(300), nullable=False, unique=True),
        sa.Column("lab_id", sa.String(64), sa.ForeignKey("labs.id"), nullable=False, index=True),
        sa.Column("device_id", sa.Integer, sa.ForeignKey("devices.id"), nullable=False, index=True),
        sa.Column("serial", sa.String(200)),
        sa.Column("spec_version", sa.String(16), nullable=False),
        sa.Column("implementation_name", sa.String(200), nullable=False),
        sa.Column("implementation_version", sa.String(100), nullable=False),
        sa.Column("session_id", sa.String(200), nullable=False),
        sa.Column("manifest_sha256", sa.String(64), nullable=False),
        sa.Column("supersedes_id", sa.String(32), sa.ForeignKey("submissions.id"), unique=True),
        sa.Column("verification", sa.String(16), nullable=False),
        sa.Column("verification_json", sa.Text, nullable=False),
        sa.Column("bundle_json", sa.Text, nullable=False),
        sa.Column("results_json", sa.Text, nullable=False),
        sa.Column("has_raw", sa.Boolean, nullable=False),
        sa.Column("token_id", sa.Integer, sa.ForeignKey("tokens.id"), nullable=False),
        sa.Column("received_at", tz, nullable=False, index=True),
    )
    op.create_table(
        "metric_values",
        sa.Column("submission_id", sa.String(32), sa.ForeignKey("submissions.id"), primary_key=True),
        sa.Column("metric_id", sa.String(100), primary_key=True, index=True),
        sa.Column("value", sa.Float),
        sa.Column("value_json", sa.Text, nullable=False),
        sa.Column("per_repetition_json", sa.Text, nullable=False),
        sa.Column("unit", sa.String(50), nullable=False),
        sa.Column("n", sa.Integer, nullable=False),
        sa.Column("sd_json", sa.Text, nullable=False),
        sa.Column("definition_version", sa.String(50), nullable=False),
    )
    op.create_table(
        "withdrawals",
        sa.Column("submission_id", sa.String(32), sa.ForeignKey("submissions.id"), primary_key=True),
        sa.Column("reason", sa.Text, nullable=False),
        sa.Column("token_id", sa.Integer, sa.ForeignKey("tokens.id"), nullable=False),
        sa.Column("at", tz, nullable=False),
    )
    op.create_table(
        "conformance_reports",
        sa.Column("sha256", sa.String(64), primary_key=True),
        sa.Column("implementation_name", sa.String(200), nullable=False, index=True),
        sa.Column("implementation_version", sa.String(100), nullable=False),
        sa.Column("spec_version", sa.String(16), nullable=False),
        sa.Column("report_json", sa.Text, nullable=False),
        sa.Column("submission_id", sa.String(32), sa.ForeignKey("submissions.id"), nullable=False),
        sa.Column("received_at", tz, nullable=False),
    )
    dialect = op.get_bind().dialect.name
    if dialect == "postgresql":
        op.execute(
            "CREATE FUNCTION registry_append_only() RETURNS trigger AS $$ BEGIN "
            "RAISE EXCEPTION 'registry records are append-only (%)', TG_TABLE_NAME; END $$ LANGUAGE plpgsql"
        )
    add_triggers(APPEND_ONLY)


def downgrade() -> None:
    drop_triggers(APPEND_ONLY)
    if op.get_bind().dialect.name == "postgresql":
        op.execute("DROP FUNCTION IF EXISTS registry_append_only()")
    for table in ("conformance_reports", "withdrawals", "metric_values", "submissions", "devices", "tokens", "labs"):
        op.drop_table(table)
