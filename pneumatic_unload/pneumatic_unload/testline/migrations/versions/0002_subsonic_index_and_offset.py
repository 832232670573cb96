# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Schema 2: the ISO 6358-1:2013 subsonic index m and its uncertainty [-], the transducer's
fitted zero offset and its uncertainty [Pa].

Revision ID: 0002
Revises: 0001
"""

import sqlalchemy as sa
from alembic import op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None

COLUMNS = ("subsonic_index", "subsonic_index_std", "pressure_offset", "pressure_offset_std")


def upgrade() -> None:
    with op.batch_alter_table("unloads") as b:
        for name in COLUMNS:
            b.add_column(sa.Column(name, sa.Double))
    if op.get_bind().dialect.name == "sqlite":
        op.execute("PRAGMA user_version = 2")


def downgrade() -> None:
    with op.batch_alter_table("unloads") as b:
        for name in reversed(COLUMNS):
            b.drop_column(name)
    if op.get_bind().dialect.name == "sqlite":
        op.execute("PRAGMA user_version = 1")
