"""closed_loop_items.progress: the teacher's share of the teaching done when the item was
chosen, so the page's progress bar moves with every item

Revision ID: 0006
Revises: 0005
"""

import sqlalchemy as sa
from alembic import op

revision = '0006'
down_revision = '0005'
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.add_column('closed_loop_items', sa.Column('progress', sa.Float(), nullable=True))


def downgrade() -> None:
    op.drop_column('closed_loop_items', 'progress')
