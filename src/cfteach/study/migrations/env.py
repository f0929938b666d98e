"""Alembic environment: uses the connection handed over by cfteach.study.db.upgrade."""

from alembic import context
from sqlalchemy import create_engine

from cfteach.study.models import Base

config = context.config
target = Base.metadata


def run() -> None:
    conn = config.attributes.get("connection")
    if conn is None:
        engine = create_engine(config.get_main_option("sqlalchemy.url"))
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
