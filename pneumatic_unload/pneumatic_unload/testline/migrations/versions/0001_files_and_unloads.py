# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Schema 1: a row per input (files) and per unload (unloads).

Revision ID: 0001
Revises: (none)
"""

import sqlalchemy as sa
from alembic import op

revision = "0001"
down_revision = None
branch_labels = None
depends_on = None

#: Columns of unloads taken from a result's JSON at schema 1 (SI units), frozen here.
RESULT_COLUMNS = (
    ("status", sa.Text), ("status_text", sa.Text), ("final", sa.Integer),
    ("t_start", sa.Double), ("tau_exp", sa.Double), ("tau_exp_std", sa.Double),
    ("p10", sa.Double), ("p_atm", sa.Double), ("p_star", sa.Double),
    ("initial_temperature", sa.Double), ("volume", sa.Double),
    ("conductance", sa.Double), ("conductance_std", sa.Double),
    ("conductance_model", sa.Double), ("conductance_model_std", sa.Double),
    ("critical_ratio", sa.Double), ("critical_ratio_std", sa.Double),
    ("recommended_conductance", sa.Double), ("recommended_std", sa.Double),
    ("heat_law", sa.Text), ("method", sa.Text), ("quality", sa.Double),
)


def _user_version(v: int) -> None:
    if op.get_bind().dialect.name == "sqlite":  # what the package before Alembic read
        op.execute(f"PRAGMA user_version = {v}")


def upgrade() -> None:
    op.create_table(
        "files",
        sa.Column("id", sa.Integer, primary_key=True),
        sa.Column("path", sa.Text, nullable=False),
        sa.Column("content_hash", sa.Text, nullable=False),
        sa.Column("settings_hash", sa.Text, nullable=False),
        sa.Column("part_id", sa.Text, nullable=False),
        sa.Column("part_type", sa.Text),
        sa.Column("status", sa.Text, nullable=False),
        sa.Column("reason", sa.Text),
        sa.Column("n_unloads", sa.Integer, nullable=False),
        sa.Column("settings_json", sa.Text),
        sa.Column("package_version", sa.Text, nullable=False),
        sa.Column("analysed_at", sa.Text, nullable=False),
        sa.Column("writer", sa.Text, nullable=False),
        sa.UniqueConstraint("content_hash", "settings_hash"),
    )
    op.create_table(
        "unloads",
        sa.Column("id", sa.Integer, primary_key=True),
        sa.Column("file_id", sa.Integer, sa.ForeignKey("files.id", ondelete="CASCADE"),
                  nullable=False),
        sa.Column("unload_index", sa.Integer, nullable=False),
        sa.Column("part_id", sa.Text, nullable=False),
        *[sa.Column(name, typ) for name, typ in RESULT_COLUMNS],
        sa.Column("verdict", sa.Text),
        sa.Column("verdict_reason", sa.Text),
        sa.Column("budget_json", sa.Text),
        sa.Column("curve_json", sa.Text),
        sa.Column("result_json", sa.Text, nullable=False),
        sa.UniqueConstraint("file_id", "unload_index"),
    )
    op.create_index("unloads_part", "unloads", ["part_id"])
    op.create_index("files_part", "files", ["part_id"])
    _user_version(1)


def downgrade() -> None:
    op.drop_table("unloads")
    op.drop_table("files")
    _user_version(0)
