"""The results store: SQLAlchemy models, the database engine, migrations and queries."""
