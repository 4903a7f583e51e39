"""The verification state of a re-computed submission that does not agree is called ``disagreeing``
(spec §17.3.1), not ``disagrees``: existing rows are converted — the ``verification`` column and the
top-level ``status`` of ``verification_json`` — and the downgrade converts them back. The append-only
triggers of ``submissions`` are lifted for this one statement and restored (spec §17.5).

Revision ID: r0003
Revises: r0002
"""

import json

import sqlalchemy as sa
from alembic import op

from haptify_tools.registry.migrations.append_only import add_triggers, drop_triggers

revision = "r0003"
down_revision = "r0002"
branch_labels = None
depends_on = None

OLD, NEW = "disagrees", "disagreeing"


def rename_state(old: str, new: str) -> None:
    """Every submission whose state is ``old`` gets ``new``, in its column and its verification record."""
    submissions = sa.table(
        "submissions", sa.column("id", sa.String), sa.column("verification", sa.String), sa.column("verification_json", sa.Text)
    )
    bind = op.get_bind()
    rows = bind.execute(
        sa.select(submissions.c.id, submissions.c.verification_json).where(submissions.c.verification == old)
    ).all()
    drop_triggers(("submissions",))
    for sid, record in rows:
        details = json.loads(record)
        if details.get("status") == old:
            details["status"] = new
        bind.execute(
            submissions.update().where(submissions.c.id == sid).values(verification=new, verification_json=json.dumps(details))
        )
    add_triggers(("submissions",))


def upgrade() -> None:
    rename_state(OLD, NEW)


def downgrade() -> None:
    rename_state(NEW, OLD)
