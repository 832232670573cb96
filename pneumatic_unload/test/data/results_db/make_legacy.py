# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Make schema1/2/3.sqlite: results databases written by the package's own testline/db.py
of the commits that wrote schema versions 1, 2 and 3 (before Alembic), two unloads each.

Run from the repository (git history needed): python test/data/results_db/make_legacy.py
"""

import importlib.util
import sqlite3
import subprocess
import sys
import tempfile
from pathlib import Path

OUT = Path(__file__).resolve().parent
COMMITS = ((1, "3698a63"), (2, "16c23d0"), (3, "28a23c6"))


def main() -> None:
    tmp = Path(tempfile.mkdtemp())
    for version, commit in COMMITS:
        src = subprocess.run(["git", "show", f"{commit}:pneumatic_unload/testline/db.py"],
                             check=True, capture_output=True, text=True).stdout
        (tmp / f"db{version}.py").write_text(src)
        spec = importlib.util.spec_from_file_location(f"db{version}", tmp / f"db{version}.py")
        db = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = db
        spec.loader.exec_module(db)
        assert db.SCHEMA_VERSION == version
        path = OUT / f"schema{version}.sqlite"
        path.unlink(missing_ok=True)
        con = db.open_db(path)
        for k, c in enumerate((8.001371402e-9, 0.1 + 0.2)):
            u = {"status": "ok", "status_text": "", "final": True, "t_start": 1.25 + k,
                 "tau_exp": 0.123456789012345, "recommended_conductance": c,
                 "recommended_std": 1.2345678901234567e-11, "conductance": c,
                 "heat_law": "adiabatic", "critical_ratio": 0.4, "verdict": "pass",
                 "verdict_reason": "within specification",
                 "curve": {"t": [0.0, 0.1], "p": [6e5, 5e5]}}
            if version >= 2:
                u.update(subsonic_index=0.5, pressure_offset=12.5)
            if version >= 3:
                u.update(direction="charge" if k else "discharge",
                         supply_pressure=6e5 if k else None)
            rec = db.FileRecord(path=f"/bags/V14-00{k}_run0", content_hash=f"c{version}{k}",
                                settings_hash="s", part_id=f"V14-00{k}", status="ok",
                                unloads=[u], settings={"volume": 1e-3}, part_type="g14",
                                writer="batch", package_version=f"schema-{version}")
            assert db.write_file(con, rec)
        con.close()
        c2 = sqlite3.connect(path)
        c2.execute("VACUUM")
        c2.close()
        print(path, path.stat().st_size)


if __name__ == "__main__":
    main()
