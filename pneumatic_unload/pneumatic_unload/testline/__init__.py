# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The test line: many inputs analysed in batch (on Dask), the results database, the
specifications parts are judged against.

* :mod:`~pneumatic_unload.testline.db` - the results database (an embedded SQLite file or
  a PostgreSQL server): one row per input and per unload, export to CSV and Parquet;
* :mod:`~pneumatic_unload.testline.schema` - its schema, backends and Alembic migrations;
* :mod:`~pneumatic_unload.testline.spec` - part types' C, b and sigma limits (YAML);
* :mod:`~pneumatic_unload.testline.job` - one input: read, analyse, judge (a worker's job);
* :mod:`~pneumatic_unload.testline.accounting` - where a batch's CPU seconds and idle time
  go (per task, per process and thread);
* :mod:`~pneumatic_unload.testline.batch` - the batch: skip what is done, run on Dask,
  write as it completes; the parts table (mean, repeatability, verdict).
"""

from pneumatic_unload.testline.batch import (
    BatchError,
    BatchResult,
    discover,
    part_summary,
    progress_bar,
    run_batch,
)
from pneumatic_unload.testline.db import (
    FileRecord,
    ResultsDB,
    ResultsDBError,
    export,
    open_db,
    unload_rows,
    write_file,
    write_table,
)
from pneumatic_unload.testline.job import InputOptions, analyze_file
from pneumatic_unload.testline.spec import Spec, SpecError, load_spec, parse_spec

__all__ = ["BatchError", "BatchResult", "FileRecord", "InputOptions", "ResultsDB",
           "ResultsDBError", "Spec", "SpecError", "analyze_file", "discover", "export",
           "load_spec", "open_db", "parse_spec", "part_summary", "progress_bar", "run_batch",
           "unload_rows", "write_file", "write_table"]
