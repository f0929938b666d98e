"""closed_loop_items: the items the live closed-loop teacher showed each participant

Revision ID: 0005
Revises: 0004
"""

import sqlalchemy as sa
from alembic import op

revision = '0005'
down_revision = '0004'
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table('closed_loop_items',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('session_pk', sa.Integer(), nullable=False),
    sa.Column('domain', sa.String(length=64), nullable=False),
    sa.Column('position', sa.Integer(), nullable=False),
    sa.Column('kind', sa.String(length=16), nullable=False),
    sa.Column('purpose', sa.String(length=16), nullable=False),
    sa.Column('demo', sa.Integer(), nullable=False),
    sa.Column('about', sa.Integer(), nullable=True),
    sa.Column('env_code', sa.String(length=64), nullable=False),
    sa.Column('env_index', sa.Integer(), nullable=False),
    sa.Column('start_state', sa.JSON(), nullable=False),
    sa.Column('expected_area', sa.Float(), nullable=False),
    sa.Column('predicted_optimal', sa.Float(), nullable=True),
    sa.Column('predicted_held_out', sa.Float(), nullable=True),
    sa.Column('shown_at', sa.DateTime(timezone=True), nullable=False),
    sa.Column('done_at', sa.DateTime(timezone=True), nullable=True),
    sa.Column('server_ms', sa.Integer(), nullable=True),
    sa.Column('actions', sa.Text(), nullable=True),
    sa.Column('reward', sa.Float(), nullable=True),
    sa.Column('optimal_reward', sa.Float(), nullable=True),
    sa.Column('optimal', sa.Boolean(), nullable=True),
    sa.ForeignKeyConstraint(['session_pk'], ['sessions.id'], ),
    sa.PrimaryKeyConstraint('id'),
    sa.UniqueConstraint('session_pk', 'domain', 'position',
                        name='uq_closed_loop_items_position')
    )
    with op.batch_alter_table('closed_loop_items', schema=None) as batch_op:
        batch_op.create_index(batch_op.f('ix_closed_loop_items_session_pk'), ['session_pk'],
                              unique=False)


def downgrade() -> None:
    with op.batch_alter_table('closed_loop_items', schema=None) as batch_op:
        batch_op.drop_index(batch_op.f('ix_closed_loop_items_session_pk'))
    op.drop_table('closed_loop_items')
