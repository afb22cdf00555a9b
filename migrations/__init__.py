"""Alembic migrations of the results store, shipped inside the package.

Run them with ``finaldrive db upgrade`` (see :mod:`service.db.migrate`).
"""
