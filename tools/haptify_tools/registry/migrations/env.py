"""Alembic environment of the registry: migrations run on the connection the application passes in
(``haptify_tools.registry.db.migrate``), never on a URL from a configuration file."""

from __future__ import annotations

from alembic import context

from haptify_tools.registry.db import Base

connection = context.config.attributes["connection"]
context.configure(connection=connection, target_metadata=Base.metadata, render_as_batch=connection.dialect.name == "sqlite")
context.run_migrations()
