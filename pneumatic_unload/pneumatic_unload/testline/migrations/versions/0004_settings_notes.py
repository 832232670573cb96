# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Schema 4: an input's settings notes (where a command-line setting met a different value
recorded in the input: which one was used, and why; NULL in older rows and where none
did).

Revision ID: 0004
Revises: 0003
"""

import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("files") as b:
        b.add_column(sa.Column("settings_notes", sa.Text))
    if op.get_bind().dialect.name == "sqlite":
        op.execute("PRAGMA user_version = 4")


def downgrade() -> None:
    with op.batch_alter_table("files") as b:
        b.drop_column("settings_notes")
    if op.get_bind().dialect.name == "sqlite":
        op.execute("PRAGMA user_version = 3")
