"""The append-only rule of the registry's records as database triggers (spec §17.5), shared by the
migrations: on PostgreSQL a trigger per table calling ``registry_append_only()`` (created by r0001), on
SQLite one trigger per table and statement."""

from __future__ import annotations

from alembic import op


def add_triggers(tables: tuple[str, ...]) -> None:
    """Refuse UPDATE and DELETE on ``tables``."""
    dialect = op.get_bind().dialect.name
    for table in tables:
        if dialect == "postgresql":
            op.execute(
                f"CREATE TRIGGER {table}_append_only BEFORE UPDATE OR DELETE ON {table} "
                "FOR EACH ROW EXECUTE FUNCTION registry_append_only()"
            )
        elif dialect == "sqlite":
            for action in ("UPDATE", "DELETE"):
                op.execute(
                    f"CREATE TRIGGER {table}_no_{action.lower()} BEFORE {action} ON {table} "
                    f"BEGIN SELECT RAISE(ABORT, 'registry records are append-only ({table})'); END"
                )


def drop_triggers(tables: tuple[str, ...]) -> None:
    """Remove the triggers of :func:`add_triggers` from ``tables``."""
    dialect = op.get_bind().dialect.name
    for table in tables:
        if dialect == "postgresql":
            op.execute(f"DROP TRIGGER IF EXISTS {table}_append_only ON {table}")
        elif dialect == "sqlite":
            for action in ("update", "delete"):
                op.execute(f"DROP TRIGGER IF EXISTS {table}_no_{action}")


def create_tables(tables: dict[str, list]) -> None:
    """Create each table (name → its columns and constraints) in order, then make them append-only."""
    for name, columns in tables.items():
        op.create_table(name, *columns)
    add_triggers(tuple(tables))


def drop_tables(tables: tuple[str, ...]) -> None:
    """Undo :func:`create_tables`: the triggers, then the tables in reverse order."""
    drop_triggers(tables)
    for name in reversed(tables):
        op.drop_table(name)
