# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Schema 3: the flow's direction ('discharge' or 'charge'; NULL in older rows: discharges)
and a charge's supply pressure [Pa absolute].

Revision ID: 0003
Revises: 0002
"""

import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("unloads") as b:
        b.add_column(sa.Column("direction", sa.Text))
        b.add_column(sa.Column("supply_pressure", sa.Double))
    if op.get_bind().dialect.name == "sqlite":
        op.execute("PRAGMA user_version = 3")


def downgrade() -> None:
    with op.batch_alter_table("unloads") as b:
        b.drop_column("supply_pressure")
        b.drop_column("direction")
    if op.get_bind().dialect.name == "sqlite":
        op.execute("PRAGMA user_version = 2")
