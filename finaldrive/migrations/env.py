"""Alembic environment: metadata from service.db.models, batch mode for SQLite.

The database URL comes from the Alembic config (``sqlalchemy.url``, set by
service.db.migrate) and connections get the service's SQLite pragmas.
"""

from __future__ import annotations

from alembic import context

from finaldrive.service.db.engine import make_engine
from finaldrive.service.db.models import Base

config = context.config
target_metadata = Base.metadata


def run_migrations_offline() -> None:
    context.configure(
        url=config.get_main_option("sqlalchemy.url"),
        target_metadata=target_metadata,
        literal_binds=True,
        render_as_batch=True,
    )
    with context.begin_transaction():
        context.run_migrations()


def run_migrations_online() -> None:
    engine = make_engine(config.get_main_option("sqlalchemy.url") or "")
    try:
        with engine.connect() as connection:
            context.configure(connection=connection, target_metadata=target_metadata, render_as_batch=True)
            with context.begin_transaction():
                context.run_migrations()
    finally:
        engine.dispose()


if context.is_offline_mode():
    run_migrations_offline()
else:
    run_migrations_online()
