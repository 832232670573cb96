# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Bounded bag reading (pneumatic_unload.io.bag.inflate): crafted chunks that claim or
expand to gigabytes are refused with a BagFormatError before they are allocated, on every
read path (the numpy fast path, rosbags' reader, recover) and in the CLI."""

from __future__ import annotations

import json
import re
import shutil
import struct
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from bagbombs import make_bomb
from mcap.reader import make_reader

from pneumatic_unload.analysis.runs import write_simulated_bag
from pneumatic_unload.config import RigConfig
from pneumatic_unload.io import TOPIC_PRESSURE, BagFormatError, read_pressure, recover
from pneumatic_unload.io.bag.inflate import MAX_CHUNK_BYTES, MAX_INFLATION, inflate
from pneumatic_unload.io.bag.reader import fast_raw_pairs, read_stamped_pairs
from pneumatic_unload.io.bag.schema import MSGTYPE_PRESSURE

GIB = 1 << 30
#: Peak resident memory a refused bomb may cost a reading process [MiB]: the interpreter
#: with numpy and rosbags takes about 100; a bomb read whole takes 2 100 (2 GiB) and more.
RSS_BOUND_MIB = 512


@pytest.fixture(scope="module")
def good_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("good")
    cfg = RigConfig(volume=1e-3, conductance=5e-9, duration=2.5, pre_time=0.3,
                    noise_std=500.0, seed=1)
    write_simulated_bag(cfg, d / "bag", analyze_live=False)
    return d / "bag"


def _bomb(good_bag: Path, tmp_path: Path, name: str = "bomb", **kw: object) -> Path:
    bag = tmp_path / name
    shutil.copytree(good_bag, bag)
    make_bomb(bag, **kw)  # type: ignore[arg-type]
    return bag


_PROBE = textwrap.dedent("""
    import json, resource, sys
    from pathlib import Path
    from pneumatic_unload.io.bag.reader import fast_raw_pairs, read_stamped_pairs
    path, how = Path(sys.argv[1]), sys.argv[2]
    try:
        if how == "fast":
            (f,) = sorted(path.glob("*.mcap"))
            fast_raw_pairs(f, "/tank/pressure", "sensor_msgs/msg/FluidPressure")
        else:
            read_stamped_pairs(path, "/tank/pressure", "sensor_msgs/msg/FluidPressure",
                               fast=how == "read")
        out = {"error": None}
    except BaseException as exc:
        from pneumatic_unload.io import BagFormatError
        name = "BagFormatError" if isinstance(exc, BagFormatError) else type(exc).__name__
        out = {"error": name, "message": str(exc)}
    out["peak_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(json.dumps(out))
""")


def _probe(bag: Path, how: str) -> dict:
    """Read ``bag`` in a fresh process (``how``: 'fast' the numpy path alone, 'read'
    read_stamped_pairs, 'rosbags' its generic path); the error and the peak RSS."""
    p = subprocess.run([sys.executable, "-c", _PROBE, str(bag), how], capture_output=True,
                       text=True, timeout=300, check=True)
    return json.loads(p.stdout)


@pytest.mark.parametrize("how", ["fast", "read", "rosbags"])
def test_a_2_gib_zstd_bomb_is_refused_before_it_is_allocated(good_bag: Path, tmp_path: Path,
                                                             how: str):
    bag = _bomb(good_bag, tmp_path, extra=2 * GIB)  # the chunk states 2 GiB, truly
    assert (bag / "bag.mcap").stat().st_size < 1_000_000
    out = _probe(bag, how)
    assert out["error"] == "BagFormatError", out
    claimed = re.search(r"claims (\d+) bytes", out["message"])
    assert claimed and int(claimed[1]) > 2 * GIB and "MAX_CHUNK_BYTES" in out["message"]
    assert out["peak_mib"] < RSS_BOUND_MIB


@pytest.mark.parametrize("how", ["fast", "read", "rosbags"])
def test_a_chunk_that_expands_past_its_claim_is_cut_at_the_claim(good_bag: Path,
                                                                 tmp_path: Path, how: str):
    """The chunk claims its records' size and hides 2 GiB of zeros behind them."""
    bag = _bomb(good_bag, tmp_path, extra=2 * GIB, claim="records")
    out = _probe(bag, how)
    assert out["error"] == "BagFormatError", out
    assert "expands to more than" in out["message"]
    assert out["peak_mib"] < RSS_BOUND_MIB


def test_a_chunk_claiming_a_tebibyte_is_a_format_error_not_a_memory_error(good_bag: Path,
                                                                           tmp_path: Path):
    bag = _bomb(good_bag, tmp_path, extra=1 << 20, claim=1 << 40, frame_size=False)
    (mcap_file,) = bag.glob("*.mcap")
    with pytest.raises(BagFormatError, match=f"claims {1 << 40} bytes"):
        fast_raw_pairs(mcap_file, TOPIC_PRESSURE, MSGTYPE_PRESSURE)
    with pytest.raises(BagFormatError, match="MAX_CHUNK_BYTES"):
        read_pressure(bag)


def test_an_lz4_bomb_is_refused(good_bag: Path, tmp_path: Path):
    bag = _bomb(good_bag, tmp_path, extra=256 << 20, compression="lz4")
    (mcap_file,) = bag.glob("*.mcap")
    with pytest.raises(BagFormatError, match="MAX_CHUNK_BYTES"):
        fast_raw_pairs(mcap_file, TOPIC_PRESSURE, MSGTYPE_PRESSURE)
    liar = _bomb(good_bag, tmp_path, "liar", extra=256 << 20, compression="lz4",
                 claim="records")
    for fast in (True, False):
        with pytest.raises(BagFormatError, match="expands to more than"):
            read_stamped_pairs(liar, TOPIC_PRESSURE, MSGTYPE_PRESSURE, fast=fast)


def test_chunks_each_below_the_cap_but_past_the_bags_budget_are_refused(good_bag: Path,
                                                                        tmp_path: Path):
    """Several honest chunks of 40 MiB of zeros: each under MAX_CHUNK_BYTES, together
    more than MAX_INFLATION times the file's size."""
    bag = _bomb(good_bag, tmp_path, extra=40 << 20, chunk_size=40_000)
    (mcap_file,) = bag.glob("*.mcap")
    size = mcap_file.stat().st_size
    assert 3 * (40 << 20) > MAX_INFLATION * size  # the crafted file is past its budget
    for fast in (True, False):
        with pytest.raises(BagFormatError, match="decompress to more than"):
            read_stamped_pairs(bag, TOPIC_PRESSURE, MSGTYPE_PRESSURE, fast=fast)
    with pytest.raises(BagFormatError, match="decompress to more than"):
        fast_raw_pairs(mcap_file, TOPIC_PRESSURE, MSGTYPE_PRESSURE)


def test_a_good_compressed_chunk_reads_the_same(good_bag: Path, tmp_path: Path):
    """The bounded path returns what the bag holds (a zstd and an lz4 rewrite, no zeros)."""
    t_ref, p_ref = read_pressure(good_bag)
    for comp in ("zstd", "lz4"):
        bag = _bomb(good_bag, tmp_path, comp, extra=0, compression=comp, chunk_size=50_000)
        for fast in (True, False):
            t, p, _ = read_stamped_pairs(bag, TOPIC_PRESSURE, MSGTYPE_PRESSURE, fast=fast)
            assert (t == t_ref).all() and (p == p_ref).all()


def test_inflate_refuses_what_it_cannot_bound():
    import zstandard

    with pytest.raises(BagFormatError, match="MAX_CHUNK_BYTES"):
        inflate("zstd", b"", MAX_CHUNK_BYTES + 1, "a chunk")
    with pytest.raises(BagFormatError, match="expands to 3 bytes, not the 4"):
        inflate("zstd", zstandard.compress(b"abc"), 4, "a chunk")
    with pytest.raises(BagFormatError, match="does not decompress"):
        inflate("lz4", b"not lz4", 10, "a chunk")
    with pytest.raises(BagFormatError, match="unknown compression"):
        inflate("brotli", b"", 0, "a chunk")


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "pneumatic_unload.app.cli", *args],
                          capture_output=True, text=True, timeout=120)


def test_analyze_and_recover_of_a_bomb_exit_with_one_line(good_bag: Path, tmp_path: Path):
    bag = _bomb(good_bag, tmp_path, extra=2 * GIB)
    p = _cli("analyze", str(bag))
    assert p.returncode == 2 and "Traceback" not in p.stderr, p.stderr
    assert "MAX_CHUNK_BYTES" in p.stderr and len(p.stderr.strip().splitlines()) == 1
    (bag / "metadata.yaml").unlink()  # as a killed writer leaves it: recover reads it all
    p = _cli("recover", str(bag))
    assert p.returncode != 0 and "Traceback" not in p.stderr, p.stderr
    assert "no pressure sample" in p.stderr
    assert "dropped 1 corrupt or oversized chunks" in p.stdout


def test_recover_keeps_the_good_and_drops_the_bomb(good_bag: Path, tmp_path: Path):
    """A bag of several chunks, one crafted: recover keeps the others and says so."""
    bag = tmp_path / "mixed"
    shutil.copytree(good_bag, bag)
    make_bomb(bag, extra=0, chunk_size=40_000)  # good zstd chunks
    with (bag / "bag.mcap").open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and len(summary.chunk_indexes) >= 3
    second = sorted(c.chunk_start_offset for c in summary.chunk_indexes)[1]
    blob = bytearray((bag / "bag.mcap").read_bytes())
    # the second chunk's claimed size set to 1 TiB (its record: opcode, length, start and
    # end times, then the claimed size)
    struct.pack_into("<Q", blob, second + 25, 1 << 40)
    (bag / "bag.mcap").write_bytes(bytes(blob))
    (bag / "metadata.yaml").unlink()
    report = recover(bag)
    assert report.dropped_chunks >= 1
    assert 0 < report.messages[TOPIC_PRESSURE] < len(read_pressure(good_bag).p)
