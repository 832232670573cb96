# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""A bag that runs out of room (issue 54 finding 9: the recorder on a full disk exited 1
with a BagWriteError traceback and no metadata.yaml, after spamming one error per message).

The disk is made full with a file-size limit (RLIMIT_FSIZE, SIGXFSZ ignored: writes past it
fail with EFBIG, as a full disk's fail with ENOSPC; both are DISK_FULL_ERRNOS), set in a
child process only. The writer stops at the first failure, cuts the file back to its last
flush and completes the bag (summary and metadata.yaml, or metadata.yaml alone when the
summary does not fit); the recorder node then exits 1 with one clear line.
"""

from __future__ import annotations

import json
import os
import resource
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from pneumatic_unload.app.launch import ros_args
from pneumatic_unload.io.bag import BagFormatError, read_pressure, recover

#: File-size limit of the child processes [bytes]: a few seconds of a 1 kHz rig.
LIMIT = 200_000

_WRITER = textwrap.dedent("""
    import json, resource, signal, sys
    import numpy as np
    from pneumatic_unload.io.bag.errors import BagDiskFullError
    from pneumatic_unload.io.bag.recorder import BagRecorder
    from pneumatic_unload.io.bag import writer
    out, limit, summary_fits = sys.argv[1], int(sys.argv[2]), sys.argv[3] == "1"
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, resource.RLIM_INFINITY))
    if not summary_fits:  # the summary meets a full disk too
        def close(self, version, metadata):
            raise OSError(28, "No space left on device")
        writer.FlushingMcapWriter.close = close
    rec = BagRecorder(out, config={"volume": 1e-3}, flush_interval=0.0)
    sent, error = 0, ""
    for k in range(2000):
        t = (1_800_000_000 * 10**9 + np.arange(k * 100, (k + 1) * 100) * 10**6)
        try:
            rec.write_pressures(t.astype(np.int64), np.full(100, 5e5))
        except BagDiskFullError as exc:
            error = str(exc)
            break
        sent += 100
    try:  # stopped: every later write says so at once
        rec.write_pressures(np.array([2 * 10**18], dtype=np.int64), np.array([5e5]))
    except BagDiskFullError:
        pass
    rec.close()
    print(json.dumps({"sent": sent, "error": error, "held": rec.message_counts,
                      "summary": rec.summary_written}))
""")


@pytest.mark.parametrize("summary_fits", [True, False])
def test_a_bag_that_runs_out_of_room_is_completed_with_what_reached_the_disk(
        tmp_path: Path, summary_fits: bool) -> None:
    bag = tmp_path / "bag"
    out = subprocess.run([sys.executable, "-c", _WRITER, str(bag), str(LIMIT),
                          "1" if summary_fits else "0"], capture_output=True, text=True,
                         timeout=120)
    # before: BagWriteError traceback at close, no metadata.yaml, a torn last record
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout)
    assert "File too large (errno EFBIG): no more room, recording stopped" in got["error"]
    assert (bag / "metadata.yaml").is_file()
    assert (bag / "bag.mcap").stat().st_size <= LIMIT
    assert got["summary"] is summary_fits
    if not summary_fits:  # metadata.yaml, and a data section that recover completes
        with pytest.raises(BagFormatError, match="pneumatic-unload recover"):
            read_pressure(bag)
        assert recover(bag).messages["/tank/pressure"] == got["sent"]
    t_ns, p = read_pressure(bag)[:2]
    # every message the writer accepted before the failure (its last flush was at the
    # write before it: flush_interval 0), in order, none torn
    assert len(p) == got["sent"] == got["held"]["/tank/pressure"] > 1000
    assert (t_ns[1:] > t_ns[:-1]).all()


def _limited() -> None:
    """In the child: the file-size limit, SIGXFSZ ignored (writes fail with EFBIG)."""
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (LIMIT, resource.RLIM_INFINITY))


@pytest.mark.serial
def test_the_recorder_on_a_full_disk_stops_completes_its_bag_and_exits_clearly(
        tmp_path: Path) -> None:
    pytest.importorskip("rclpy")
    bag = tmp_path / "run"
    env = {**os.environ, "TMPDIR": str(tmp_path)}
    rec_log, sim_log = tmp_path / "recorder.log", tmp_path / "simulator.log"
    with open(rec_log, "w") as rl, open(sim_log, "w") as sl:
        rec = subprocess.Popen([sys.executable, "-m", "pneumatic_unload.nodes.recorder",
                                "--ros-args", *ros_args({"output": str(bag)})],
                               env=env, preexec_fn=_limited, stdout=rl,
                               stderr=subprocess.STDOUT)
        sim = subprocess.Popen([sys.executable, "-m", "pneumatic_unload.nodes.simulator",
                                "--ros-args", *ros_args({"duration": 8.0, "start_delay": 0.5,
                                                         "wait_for_subscribers": 1})],
                               env=env, stdout=sl, stderr=subprocess.STDOUT)
        try:
            deadline = time.monotonic() + 90.0
            while rec.poll() is None and time.monotonic() < deadline:
                time.sleep(0.2)
            # before: it ran on, one error per message, until stopped (then exit 1, a
            # traceback); now it stops by itself at the full disk
            assert rec.poll() is not None, rec_log.read_text()[-3000:]
        finally:
            for proc in (rec, sim):
                if proc.poll() is None:
                    proc.send_signal(signal.SIGINT)
                    try:
                        proc.wait(timeout=20)
                    except subprocess.TimeoutExpired:
                        proc.kill()
                        proc.wait()
    text = rec_log.read_text()
    assert rec.returncode == 1, text[-3000:]
    assert "Traceback" not in text and "BagWriteError" not in text
    assert "recorder: error: recording stopped, no room left" in text
    assert "metadata.yaml written" in text
    assert text.count("not recorded") == 1  # said once, not per message
    assert (bag / "metadata.yaml").is_file()
    # the bag reads: what reached the disk, its pressure samples in order
    t_ns, p = read_pressure(bag)[:2]
    assert len(p) > 1000 and (t_ns[1:] > t_ns[:-1]).all()
