"""Alembic environment: uses the connection handed over by cfteach.study.db.upgrade."""

from alembic import context
from sqlalchemy import create_engine

from cfteach.study.models import Base

config = context.config
target = Base.metadata


def run() -> None:
    conn = config.attributes.get("connection")
    if conn is None:
        url = config.get_main_option("sqlalchemy.url")
        if url is None:  # db.alembic_config always sets it
            raise RuntimeError("no database URL: set sqlalchemy.url")
        engine = create_engine(url)
        with engine.connect() as c:
            _migrate(c)
            c.commit()
    else:
        _migrate(conn)


def _migrate(conn) -> None:  # noqa: ANN001
    context.configure(connection=conn, target_metadata=target, render_as_batch=True)
    with context.begin_transaction():
        context.run_migrations()


run()
