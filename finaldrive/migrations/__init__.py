"""Alembic migrations of the results store, shipped inside the package.

Run them with ``finaldrive db upgrade`` (see :mod:`service.db.migrate`).
"""

if __name__ != "finaldrive.migrations":  # never importable as a top-level `migrations` (it would shadow others)
    raise ImportError(f"this is finaldrive.migrations; import it by that name, not as {__name__!r}")
