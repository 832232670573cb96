# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Node parameters (issue 13): one list per node (pneumatic_unload.config.nodes) that the
node declares, ``--help`` prints (exit 0, ROS not started, also after ``--ros-args``) and
``config/<node>.yaml`` holds with ranges in comments; the files cannot drift from it."""

import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from pneumatic_unload.config.nodes import NODES, help_text, node_parameters, yaml_text

ROOT = Path(__file__).resolve().parents[1]
ENV = dict(os.environ, PYTHONPATH=str(ROOT))


def _node(name: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", f"pneumatic_unload.nodes.{name}", *args],
                          capture_output=True, text=True, timeout=60, env=ENV, cwd=ROOT)


@pytest.mark.parametrize("node", list(NODES))
def test_yaml_file_is_the_nodes_parameter_list(node):
    path = ROOT / "config" / f"{node}.yaml"
    assert path.read_text() == yaml_text(node), (
        f"config/{node}.yaml drifted: regenerate it with pneumatic_unload.config.nodes."
        "yaml_text")
    specs = node_parameters(node)
    params = yaml.safe_load(path.read_text())["/**"]["ros__parameters"]
    arrays = {n for n, s in specs.items() if s.kind == "string_array"}
    assert set(params) == set(specs) - arrays  # unset arrays are commented (no empty list)
    for name in arrays:
        assert f"# {name}: [" in path.read_text()
    for line in path.read_text().splitlines():
        for name, s in specs.items():
            if line.strip().startswith(f"{name}:") and s.kind in ("double", "integer"):
                assert ", range [" in line, line
    for name, value in params.items():
        s = specs[name]
        if s.lo is not None:
            assert s.lo <= value <= s.hi, name
        if s.choices:
            assert value in s.choices, name


@pytest.mark.parametrize("node", list(NODES))
@pytest.mark.parametrize("args", [("--help",), ("-h",), ("--ros-args", "--help")])
def test_help_lists_parameters_with_units_and_ranges_and_exits_0(node, args):
    proc = _node(node, *args)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    assert proc.stdout.strip() == help_text(node)
    for name in node_parameters(node):
        assert f"\n  {name} (" in proc.stdout
    assert "range [" in proc.stdout


def test_help_names_units():
    text = help_text("estimator")
    assert "volume (double, default 0.005)" in text and "[m^3], range [1e-07, 10]" in text
    assert "[Pa]" in text and "[K]" in text
    assert "[Hz]" in help_text("simulator")


@pytest.mark.parametrize("node,override,needle", [
    ("recorder", "split:=bogus", "split"),
    ("replay", "loop:=false", "bag is required"),
])
def test_recorder_and_replay_read_their_yaml_files(node, override, needle, tmp_path):
    # the parameter file parses (a bad file fails in rcl, before the node's own checks)
    proc = subprocess.run(
        [sys.executable, "-m", f"pneumatic_unload.nodes.{node}", "--ros-args",
         "--params-file", str(ROOT / "config" / f"{node}.yaml"), "-p", override],
        capture_output=True, text=True, timeout=60, env=ENV, cwd=tmp_path)
    assert proc.returncode == 2 and needle in proc.stderr, proc.stderr


def test_estimator_volts_input_without_calibration_is_refused(tmp_path):
    """input:=volts at signal_gain 1, signal_offset 0 (the Pa input) would take volts for
    pascals: the estimator refuses to start and says what to set."""
    proc = subprocess.run(
        [sys.executable, "-m", "pneumatic_unload.nodes.estimator", "--ros-args",
         "-p", "input:=volts"],
        capture_output=True, text=True, timeout=60, env=ENV, cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert "signal_gain" in proc.stderr and "Traceback" not in proc.stderr
