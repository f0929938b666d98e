"""client_reports: requests the server refused for good, as reported by the page

Revision ID: 0004
Revises: 0003
"""

import sqlalchemy as sa
from alembic import op

revision = '0004'
down_revision = '0003'
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table('client_reports',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('report_id', sa.String(length=64), nullable=False),
    sa.Column('session_pk', sa.Integer(), nullable=True),
    sa.Column('path', sa.String(length=100), nullable=False),
    sa.Column('http_status', sa.Integer(), nullable=False),
    sa.Column('error', sa.String(length=64), nullable=False),
    sa.Column('detail', sa.Text(), nullable=False),
    sa.Column('event', sa.JSON(), nullable=True),
    sa.Column('client_ms', sa.Float(), nullable=True),
    sa.Column('server_at', sa.DateTime(timezone=True), nullable=False),
    sa.ForeignKeyConstraint(['session_pk'], ['sessions.id'], ),
    sa.PrimaryKeyConstraint('id'),
    sa.UniqueConstraint('report_id')
    )
    with op.batch_alter_table('client_reports', schema=None) as batch_op:
        batch_op.create_index(batch_op.f('ix_client_reports_session_pk'), ['session_pk'],
                              unique=False)


def downgrade() -> None:
    with op.batch_alter_table('client_reports', schema=None) as batch_op:
        batch_op.drop_index(batch_op.f('ix_client_reports_session_pk'))
    op.drop_table('client_reports')
