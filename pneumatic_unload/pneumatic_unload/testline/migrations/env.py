# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Alembic environment of the results database.

Run by :func:`pneumatic_unload.testline.schema.migrate` with its connection (in
``config.attributes['connection']``), inside that connection's transaction (which holds the
schema lock). Not a module of the package: this folder has no ``__init__.py``.
"""

from alembic import context

if context.is_offline_mode():
    raise SystemExit("the results database's migrations run online only (open_db runs them)")
connection = context.config.attributes.get("connection")
if connection is None:
    raise SystemExit("run the migrations through pneumatic_unload.testline.db.open_db")
# SQLite alters a table by copying it (batch mode); its DDL is transactional here because
# the caller holds an explicit transaction (BEGIN IMMEDIATE)
context.configure(connection=connection, render_as_batch=connection.dialect.name == "sqlite",
                  transactional_ddl=True)
with context.begin_transaction():
    context.run_migrations()
