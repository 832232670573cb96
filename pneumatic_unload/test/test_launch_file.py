# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The launch file ``launch/bench.launch.yaml`` (ROS 2 YAML launch format, #27's first
part): the package's launcher reads and runs the very file ``ros2 launch`` would, over
real DDS, and stops on Ctrl-C with every node's clean exit."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import time
from pathlib import Path

import pytest

from pneumatic_unload.app.launch import LaunchError, free_domain_id, load_launch, package_share

#: run alone, after the parallel part of make test (see conftest.py)
pytestmark = pytest.mark.serial

LAUNCH = Path(__file__).resolve().parent.parent / "launch" / "bench.launch.yaml"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_the_launch_file_s_nodes_arguments_and_parameter_files() -> None:
    nodes = {n["name"]: n for n in load_launch(LAUNCH, {"volume": "0.001",
                                                        "direction": "both"})}
    assert set(nodes) == {"simulator", "estimator", "recorder", "opcua"}
    share = package_share()
    for name, n in nodes.items():
        assert n["files"] == [share / "config" / f"{name}.yaml"]
        assert n["files"][0].is_file()
    assert nodes["simulator"]["params"]["volume"] == 0.001  # typed as ROS types it
    assert nodes["estimator"]["params"]["direction"] == "both"
    assert nodes["estimator"]["params"]["results_db"] == ""  # an empty string kept
    assert nodes["simulator"]["params"]["start_delay"] == -1.0  # the default
    assert nodes["opcua"]["params"]["endpoint"] == "opc.tcp://127.0.0.1:4840/pneumatic_unload/"
    assert nodes["opcua"]["params"]["security_policy"] == "None"  # a string, not null


@pytest.mark.parametrize("text", ["2000", "2000.0"])
def test_a_double_argument_takes_an_integer_text_as_ros2_launch_does(text: str) -> None:
    """``rate:=2000`` and ``rate:=2000.0`` alike: the launch file gives the ``param`` a
    ``type`` (launch_ros types an untyped value by the YAML type of its text, and a node
    refuses an integer for its double parameter)."""
    nodes = {n["name"]: n for n in load_launch(LAUNCH, {"rate": text, "volume": "2",
                                                        "start_delay": "3"})}
    for name, value in [("rate", 2000.0), ("volume", 2.0), ("start_delay", 3.0)]:
        got = nodes["simulator"]["params"][name]
        assert type(got) is float and got == value, (name, got)
    assert type(nodes["estimator"]["params"]["volume"]) is float


def test_the_launcher_types_params_as_launch_ros_does(tmp_path: Path) -> None:
    """No ``type``: the YAML type of the text (an integer stays an integer, as launch_ros
    gives it); ``type: float|int|str|bool`` coerces, a text not of the type is refused."""
    f = tmp_path / "x.launch.yaml"
    f.write_text("launch:\n- arg: {name: v, default: '2000'}\n"
                 "- node: {pkg: pneumatic_unload, exec: estimator, param: [\n"
                 "  {name: a, value: '$(var v)'}, {name: b, type: float, value: '$(var v)'},\n"
                 "  {name: c, type: str, value: '$(var v)'}, {name: d, type: bool, value: '1'},\n"
                 "  {name: e, type: int, value: '$(var v)'}]}\n")
    p = load_launch(f)[0]["params"]
    assert (type(p["a"]), type(p["b"]), type(p["c"]), p["d"], type(p["e"])) == (
        int, float, str, True, int)
    with pytest.raises(LaunchError, match="not of type int"):
        load_launch(f, {"v": "2000.5"})
    f.write_text("launch:\n- node: {pkg: pneumatic_unload, exec: estimator, param: [\n"
                 "  {name: a, type: double, value: '1'}]}\n")
    with pytest.raises(LaunchError, match="type 'double' is not one of"):
        load_launch(f)


def test_the_simulator_waits_for_the_launch_s_subscribers() -> None:
    """The simulator streams, and counts its start_delay, only once the estimator and the
    recorder subscribe (a loaded machine brought the estimator up 8-17 s after the
    simulator: it missed the self-started unload)."""
    nodes = {n["name"]: n for n in load_launch(LAUNCH, {"start_delay": "1"})}
    assert nodes["simulator"]["params"]["wait_for_subscribers"] == 2
    assert {"estimator", "recorder"} <= set(nodes)


def test_the_opc_ua_bridge_is_optional_and_takes_its_port() -> None:
    """opcua:=false leaves the bridge out (a node's ``if``); opcua_port sets its endpoint."""
    assert "opcua" not in {n["name"] for n in load_launch(LAUNCH, {"opcua": "false"})}
    nodes = {n["name"]: n for n in load_launch(LAUNCH, {"opcua_port": "4855"})}
    assert nodes["opcua"]["params"]["endpoint"] == "opc.tcp://127.0.0.1:4855/pneumatic_unload/"
    nodes = {n["name"]: n for n in load_launch(LAUNCH, {
        "opcua_host": "0.0.0.0", "opcua_trusted_certs": "/etc/pki/plc",
        "opcua_revoked_certs": "/etc/pki/crl", "opcua_allow_anonymous": "true"})}
    params = nodes["opcua"]["params"]  # every security setting is a launch argument
    assert params["endpoint"] == "opc.tcp://0.0.0.0:4840/pneumatic_unload/"
    assert (params["trusted_certs"], params["revoked_certs"]) == ("/etc/pki/plc", "/etc/pki/crl")
    assert params["allow_anonymous"] is True
    from pneumatic_unload.config.nodes import node_parameters

    security = {"endpoint", "security_policy", "certificate", "private_key", "users_file",
                "allow_anonymous", "trusted_certs", "revoked_certs"}
    assert security <= set(node_parameters("opcua")) and security <= set(params)
    with pytest.raises(LaunchError, match="not true or false"):
        load_launch(LAUNCH, {"opcua": "maybe"})


@pytest.mark.parametrize(("text", "given", "why"), [
    ("launch:\n- arg: {name: a}\n", {}, "no default"),
    ("launch:\n- arg: {name: a, default: '1'}\n", {"b": "2"}, "unknown launch argument"),
    ("launch:\n- node: {pkg: other, exec: x}\n", {}, "this launcher runs"),
    ("launch:\n- node: {pkg: pneumatic_unload, exec: estimator, param: "
     "[{name: v, value: '$(var nope)'}]}\n", {}, "no such argument"),
    ("launch:\n- include: {file: x.yaml}\n", {}, "not supported"),
    ("nodes: []\n", {}, "not a ROS 2 YAML launch file"),
])
def test_a_launch_file_it_cannot_run_is_refused_with_the_reason(
        tmp_path: Path, text: str, given: dict[str, str], why: str) -> None:
    f = tmp_path / "x.launch.yaml"
    f.write_text(text)
    with pytest.raises(LaunchError, match=why):
        load_launch(f, given)


def test_env_substitution_with_a_default(tmp_path: Path,
                                         monkeypatch: pytest.MonkeyPatch) -> None:
    f = tmp_path / "x.launch.yaml"
    f.write_text("launch:\n- arg: {name: v, default: '$(env PU_TEST_V 0.003)'}\n"
                 "- node: {pkg: pneumatic_unload, exec: estimator, param: "
                 "[{name: volume, value: '$(var v)'}]}\n")
    assert load_launch(f)[0]["params"]["volume"] == 0.003
    monkeypatch.setenv("PU_TEST_V", "0.004")
    assert load_launch(f)[0]["params"]["volume"] == 0.004


def test_the_launcher_runs_the_bench_and_stops_cleanly(tmp_path: Path,
                                                       venv_python: Path) -> None:
    """``python -m pneumatic_unload.app.launch launch/bench.launch.yaml name:=value``: the
    simulator opens the valve, the estimator publishes the final C (within 1 % of the
    rig's 8e-9), the recorder writes the bag; Ctrl-C stops all four (the OPC UA bridge on
    a free port), exit code 0. The arguments are integer texts (``rate:=1000``,
    ``start_delay:=1``), and the valve opens 1 s after the simulator starts streaming,
    which it does once the estimator and the recorder subscribe: on a loaded machine too
    the estimator hears the rig's plateau before it."""
    env = {**os.environ, "ROS_DOMAIN_ID": str(free_domain_id()),
           "PNEUMATIC_UNLOAD_LOG_DIR": str(tmp_path / "logs")}
    bag = tmp_path / "bag"
    # started as a shell script's background job is: SIGINT ignored, which the SIGINT
    # below (a user's kill -INT) must still stop
    proc = subprocess.Popen(
        [str(venv_python), "-m", "pneumatic_unload.app.launch", str(LAUNCH), "volume:=0.001",
         "rate:=1000", "start_delay:=1", f"output:={bag}", f"opcua_port:={_free_port()}"], env=env,
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    logs = tmp_path / "logs"
    try:
        deadline = time.monotonic() + 180.0
        final = ""
        while time.monotonic() < deadline and not final:
            time.sleep(0.5)
            for f in logs.glob("estimator-*.log"):
                final = next((ln for ln in f.read_text().splitlines() if "(final)" in ln),
                             "")
            assert proc.poll() is None, proc.stdout.read() if proc.stdout else ""
        assert final, "no final estimate within 180 s"
    finally:
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=30)
    assert proc.returncode == 0, out
    c = float(final.split("model ")[1].split(",")[0])
    assert c == pytest.approx(8e-9, rel=0.01)
    assert (bag / "metadata.yaml").is_file()


def test_a_node_started_beside_another_copy_of_the_package_runs_this_one(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A node process started from a folder that holds another ``pneumatic_unload`` (a
    checkout, an old copy) runs the package of this Python, not that one: ``python -m``
    would put the working directory first on sys.path (a bench comparing two versions
    through PYTHONPATH measured the checkout's code both times)."""
    from pneumatic_unload.app.launch import NodeProcess

    decoy = tmp_path / "pneumatic_unload"
    (decoy / "nodes").mkdir(parents=True)
    (decoy / "__init__.py").write_text("raise SystemExit('the copy in the working folder')\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("ROS_DOMAIN_ID", str(free_domain_id()))
    node = NodeProcess("simulator", {"rate": 100.0}, tmp_path / "logs")
    try:
        node.wait_output("streaming at", 60.0)
    finally:
        code = node.stop()
    assert "the copy in the working folder" not in node.output()
    assert code == 0, node.output()[-2000:]
