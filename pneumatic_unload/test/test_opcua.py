# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The OPC UA bridge (#27): the launch file's bench, a real asyncua client over loopback.

The bench is started by the package's launcher from ``launch/bench.launch.yaml`` (as
``ros2 launch`` would), the bridge on a free port, each bench on a ROS domain of its own.
A measurement of the simulated rig (V = 1 L, C = 8e-9 m^3/(s Pa)) takes about 4 s; after
it the rig vents and recharges by itself, and a Measure called meanwhile waits for the
charge (the bridge sends its goal again while the valve service answers "the tank is not
charged", for charge_wait s): a PLC calls Measure whenever Ready is True.
"""

from __future__ import annotations

import asyncio
import contextlib
import datetime
import ipaddress
import os
import signal
import socket
import subprocess
import sys
import textwrap
import time
from collections.abc import AsyncIterator, Iterator
from pathlib import Path
from typing import Any

import pytest

#: run alone, after the parallel part of make test (see conftest.py)
pytestmark = pytest.mark.serial

asyncua = pytest.importorskip("asyncua")
from asyncua import Client, ua  # noqa: E402
from asyncua.client.ua_client import UaClientState  # noqa: E402
from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256  # noqa: E402

from pneumatic_unload.app.launch import free_domain_id  # noqa: E402
from pneumatic_unload.plc import APPLICATION_URI, NAMESPACE, Outcome, hash_password  # noqa: E402

LAUNCH = Path(__file__).resolve().parent.parent / "launch" / "bench.launch.yaml"
#: The rig's conductance (the launch argument: the truth) [m^3/(s Pa)].
TRUE_C = 8e-9
#: A client's request timeout: longer than a measurement (the bridge's charge_wait 30 s,
#: measure_timeout 60 s and final_timeout 30 s bound it) [s].
CALL_TIMEOUT = 150.0


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Bench:
    """A launched bench: the launcher's process, its OPC UA port and logs."""

    def __init__(self, tmp: Path, *args: str) -> None:
        self.port = _free_port()
        self.logs = tmp / "logs"
        env = {**os.environ, "ROS_DOMAIN_ID": str(free_domain_id()),
               "PNEUMATIC_UNLOAD_LOG_DIR": str(self.logs)}
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "pneumatic_unload.app.launch", str(LAUNCH), "volume:=0.001",
             f"conductance:={TRUE_C!r}", f"opcua_port:={self.port}",
             f"output:={tmp / 'bag'}", *args],
            env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.url = f"opc.tcp://127.0.0.1:{self.port}/pneumatic_unload/"

    def log(self, node: str) -> str:
        return "\n".join(f.read_text(errors="replace") for f in self.logs.glob(f"{node}-*.log"))

    def alive(self) -> bool:
        return self.proc.poll() is None

    def stop(self) -> int:
        self.proc.send_signal(signal.SIGINT)
        out, _ = self.proc.communicate(timeout=40)
        assert self.proc.returncode == 0, out
        return self.proc.returncode


@contextlib.contextmanager
def _bench(tmp: Path, *args: str) -> Iterator[Bench]:
    bench = Bench(tmp, *args)
    try:
        yield bench
    finally:
        if bench.alive():
            bench.stop()


@contextlib.asynccontextmanager
async def _client(url: str, *, wait: float = 60.0, timeout: float = CALL_TIMEOUT,
                  **security: Any) -> AsyncIterator[tuple[Client, Any]]:
    """A connected client (asyncua's defaults but the request timeout: a 1 s watchdog),
    the bridge's object; retries the connection while the bench starts."""
    deadline = time.monotonic() + wait
    while True:
        c = Client(url, timeout=timeout)
        if security:
            c.application_uri = "urn:pneumatic-unload:test-client"
            if security.get("user"):
                c.set_user(security["user"])
                c.set_password(security["password"])
            await c.set_security(SecurityPolicyBasic256Sha256, security["certificate"],
                                 security["private_key"],
                                 server_certificate=security["server_certificate"])
        try:
            await c.connect()
            break
        except (TimeoutError, OSError, ua.UaError):
            if time.monotonic() > deadline or not security.get("retry", True):
                raise
            await asyncio.sleep(0.3)
    try:
        idx = await c.get_namespace_index(NAMESPACE)
        yield c, _Nodes(c, idx)
    finally:
        with contextlib.suppress(Exception):
            await c.disconnect()


class _Nodes:
    def __init__(self, c: Client, idx: int) -> None:
        self.c, self.idx = c, idx
        self.obj = c.get_node(ua.NodeId("PneumaticUnload", idx))

    def node(self, name: str) -> Any:
        return self.c.get_node(ua.NodeId(f"PneumaticUnload.{name}", self.idx))

    async def read(self, name: str) -> Any:
        return await self.node(name).read_value()

    async def call(self, method: str, *args: Any) -> Any:
        return await self.obj.call_method(self.node(method), *args)

    async def wait_state(self, *states: str, timeout: float = 60.0) -> str:
        deadline = time.monotonic() + timeout
        while (s := await self.read("State")) not in states:
            assert time.monotonic() < deadline, f"State {s!r}, not {states} in {timeout} s"
            await asyncio.sleep(0.2)
        return s


async def _measure(n: _Nodes, part: str) -> list[Any]:
    """Measure, called once (the bridge waits for the rig's charge itself)."""
    return await n.call("Measure", ua.Variant(part, ua.VariantType.String))


def _run(coro: Any) -> Any:
    return asyncio.run(coro)


#: The part types of the module's bench: part-* within 2 % of the rig's C, odd-* never.
SPEC = """part_types:
  part:
    match: "^part-"
    conductance: [7.84e-9, 8.16e-9]
  odd:
    match: "^odd-"
    conductance: [1.0e-9, 2.0e-9]
"""


@pytest.fixture(scope="module")
def bench(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Bench]:
    """The launch file's bench with the bridge on a free port (security None, anonymous
    sessions may measure: a lab bench), a part specification (:data:`SPEC`)."""
    tmp = tmp_path_factory.mktemp("bench")
    (tmp / "spec.yaml").write_text(SPEC)
    with _bench(tmp, f"spec_file:={tmp / 'spec.yaml'}", "opcua_allow_anonymous:=true") as b:
        yield b


def test_measure_over_opc_ua_gives_the_rigs_c(bench: Bench) -> None:
    """Done means (#27): a client calls Measure on the launched bench and gets the rig's C
    within 2 % (the final estimate's), its session alive through the call (asyncua's
    default 1 s watchdog); a second client calling Measure meanwhile is answered
    BadInvalidState at once (busy: no queue); the variables hold the estimate, with units."""

    async def main() -> None:
        async with _client(bench.url) as (c1, n1), _client(bench.url) as (c2, n2):
            await n1.wait_state("ready")  # the bridge found the estimator's action server
            results = await asyncio.gather(
                n1.call("Measure", "part-A"), n2.call("Measure", "part-B"),
                return_exceptions=True)
            ok = [r for r in results if isinstance(r, list)]
            busy = [r for r in results if isinstance(r, ua.uaerrors.BadInvalidState)]
            assert len(ok) == 1 and len(busy) == 1, results
            c, b, verdict = ok[0]
            assert c == pytest.approx(TRUE_C, rel=0.02)
            assert 0.0 < b < 1.0 and verdict == "pass"  # the final C against SPEC
            for client in (c1, c2):  # both sessions survived the call
                assert client.uaclient.state == UaClientState.CONNECTED
            assert await n1.read("Conductance") == c
            assert await n1.read("Verdict") == "pass"
            # State is the bridge's now: 'done', or under load 'no estimator' already (a
            # late estimator report); the measurement's outcome is Message
            assert await n2.read("State") in ("ready", "no estimator")
            assert await n2.read("MeasureDone") is True
            assert await n2.read("Message") == "ok"
            assert await n1.read("PartId") == ("part-A" if ok[0] is results[0] else "part-B")
            assert 0.0 < await n1.read("TauExp") < 10.0
            eu = await n1.c.get_node(ua.NodeId("PneumaticUnload.Conductance.EngineeringUnits",
                                               n1.idx)).read_value()
            assert eu.DisplayName.Text == "m³/(s·Pa)"
            eu = await n1.c.get_node(ua.NodeId("PneumaticUnload.TauExp.EngineeringUnits",
                                               n1.idx)).read_value()
            assert (eu.DisplayName.Text, eu.UnitId) == ("s", int.from_bytes(b"SEC", "big"))

    _run(main())
    assert bench.alive()


def test_start_and_poll(bench: Bench) -> None:
    """StartMeasure answers at once; MeasureDone goes True when the results are written
    (the verdict of a part whose type's range excludes the rig's C: fail)."""

    async def main() -> None:
        async with _client(bench.url) as (_c, n):
            await n.wait_state("ready")
            count = await n.read("MeasurementCount")
            assert await n.call("StartMeasure", "odd-C") is None  # no outputs
            assert await n.read("Ready") is False
            while not await n.read("MeasureDone"):
                await asyncio.sleep(0.2)
            assert await n.read("MeasurementCount") == count + 1
            assert await n.read("PartId") == "odd-C"
            # started while the rig may still recharge after the last test's unload: the
            # bridge waited for the charge (its Message 'ok', not "not charged")
            assert await n.read("Message") == "ok"
            assert await n.read("Conductance") == pytest.approx(TRUE_C, rel=0.02)
            assert await n.read("PartId") == "odd-C"
            assert await n.read("Verdict") == "fail"  # outside its type's range
            assert await n.read("Message") == "ok"

    _run(main())


def test_a_plc_waits_for_ready_measures_again_and_reads_every_result(bench: Bench) -> None:
    """As a PLC integrator sees it: the nodes resolve by browse path in the package's
    namespace (``Objects/2:PneumaticUnload/2:Ready``); after a measurement Ready is True
    (State 'ready') and a Measure called at once succeeds (the bridge waits for the rig's
    recharge); the count and time of the results grow; eq 39's C, the status, the expanded
    U and the pressures are there with their units; Charge answers; Abort stops a
    measurement, whose results then read Bad."""

    async def main() -> None:
        async with _client(bench.url) as (c, n):
            assert n.idx == 2
            obj = await c.nodes.objects.get_child("2:PneumaticUnload")
            assert obj.nodeid == n.obj.nodeid
            ready = await c.nodes.objects.get_child(["2:PneumaticUnload", "2:Ready"])
            deadline = time.monotonic() + 60.0
            while not await ready.read_value():
                assert time.monotonic() < deadline
                await asyncio.sleep(0.2)
            assert await n.read("State") == "ready"
            count = await n.read("MeasurementCount")
            for part in ("part-M", "part-N"):  # back to back: the second waits the charge
                c_meas, _b, verdict = await _measure(n, part)
                assert c_meas == pytest.approx(TRUE_C, rel=0.02) and verdict == "pass"
                assert await n.read("State") in ("ready", "no estimator")
            assert await n.read("MeasurementCount") == count + 2
            ended = await n.read("ResultTime")
            age = datetime.datetime.now(datetime.UTC) - ended.replace(tzinfo=datetime.UTC)
            assert datetime.timedelta(0) <= age < datetime.timedelta(minutes=2)
            assert await n.read("ConductanceEq39") == pytest.approx(TRUE_C, rel=0.05)
            std = await n.read("ConductanceStd")
            assert await n.read("ConductanceExpanded") == pytest.approx(2.0 * std)
            assert await n.read("Status") == "ok" and await n.read("StatusText")
            assert await n.read("InitialPressure") == pytest.approx(7e5, rel=0.01)
            assert 0.0 < await n.read("CriticalPressure") < 7e5
            assert await n.read("AtmosphericPressure") == pytest.approx(101325.0, rel=0.05)
            units = {}
            for name in ("Conductance", "ConductanceEq39", "TauExp", "InitialPressure",
                         "CriticalPressure", "CriticalRatio", "SubsonicIndex"):
                eu = await n.node(name).get_child("0:EngineeringUnits")
                info = await eu.read_value()
                assert info.NamespaceUri == "http://www.opcfoundation.org/UA/units/un/cefact"
                units[name] = info.UnitId.to_bytes(3, "big").decode()
            assert units == {"Conductance": "N45", "ConductanceEq39": "N45", "TauExp": "SEC",
                             "InitialPressure": "PAL", "CriticalPressure": "PAL",
                             "CriticalRatio": "C62", "SubsonicIndex": "C62"}
            assert await n.call("Charge") is None  # the simulator: "already charged"
            assert "charge" in await n.read("Message")
            with pytest.raises(ua.uaerrors.BadInvalidState):
                await n.call("Abort")  # nothing runs
            assert await n.call("StartMeasure", "part-O") is None
            assert await n.call("Abort") is None
            assert await n.read("MeasureDone") is True
            assert "aborted" in await n.read("Message")
            assert await n.read("MeasurementCount") == count + 3
            for name in ("Conductance", "Verdict", "Status"):
                dv = await n.node(name).read_data_value(raise_on_bad_status=False)
                assert dv.StatusCode.name == "BadRequestCancelledByClient", name
            c_meas, _b, _v = await _measure(n, "part-P")  # measuring again after it
            assert c_meas == pytest.approx(TRUE_C, rel=0.02)
            dv = await n.node("Conductance").read_data_value()
            assert dv.StatusCode.is_good()

    _run(main())
    assert bench.alive()


_DYING_CLIENT = textwrap.dedent("""
    import asyncio, sys
    from asyncua import Client, ua
    async def main():
        c = Client(sys.argv[1], timeout=120)
        await c.connect()
        idx = await c.get_namespace_index("urn:pneumatic-unload")
        obj = c.get_node(ua.NodeId("PneumaticUnload", idx))
        while True:
            print("calling", flush=True)
            try:
                print(await obj.call_method(ua.NodeId("PneumaticUnload.Measure", idx),
                                            "part-D"), flush=True)
                return
            except ua.UaError as exc:
                print("failed", exc, flush=True)
                await asyncio.sleep(0.5)
    asyncio.run(main())
""")


def test_bad_clients_leave_the_bridge_serving(bench: Bench, tmp_path: Path) -> None:
    """Malformed calls are answered with their Bad status; a client killed during its
    Measure leaves the measurement running to its end; then a Measure works."""

    async def malformed() -> None:
        async with _client(bench.url) as (_c, n):
            with pytest.raises(ua.uaerrors.BadInvalidArgument):
                await n.call("Measure", ua.Variant(3, ua.VariantType.Int32))
            with pytest.raises(ua.uaerrors.BadArgumentsMissing):
                await n.call("Measure")
            with pytest.raises(ua.uaerrors.BadTooManyArguments):
                await n.call("StartMeasure", "a", "b")
            with pytest.raises(ua.uaerrors.BadInvalidArgument):
                await n.call("StartMeasure", ua.Variant(["a"], ua.VariantType.String))

    _run(malformed())
    assert bench.alive()
    # a client killed (as a PLC losing power) while its Measure runs
    out = tmp_path / "client.out"
    with open(out, "w") as f:
        dying = subprocess.Popen([sys.executable, "-c", _DYING_CLIENT, bench.url], stdout=f,
                                 stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 60.0
        while True:  # its last call has been running for 1 s (not a refused one)
            lines = out.read_text().splitlines()
            if lines and lines[-1] == "calling" and time.time() - out.stat().st_mtime > 1.0:
                break
            assert dying.poll() is None and time.monotonic() < deadline, out.read_text()
            time.sleep(0.1)
        dying.kill()
    finally:
        dying.wait()

    async def after() -> None:
        async with _client(bench.url) as (_c, n):
            # the killed client's measurement ran to its end, its results written
            deadline = time.monotonic() + 60.0
            while not await n.read("MeasureDone"):
                assert time.monotonic() < deadline
                await asyncio.sleep(0.2)
            assert await n.read("PartId") == "part-D"
            assert await n.read("Message") == "ok"
            assert await n.read("State") in ("ready", "no estimator")  # the bridge's now
            c, _b, _v = await _measure(n, "part-E")
            assert c == pytest.approx(TRUE_C, rel=0.02)

    _run(after())
    assert bench.alive()
    assert "Traceback" not in bench.log("opcua")


# --------------------------------------------------------------------------- security
def _certificate(folder: Path, name: str, uri: str, server: bool, *,
                 valid: tuple[float, float] = (-1.0, 30.0)) -> tuple[Path, Path]:
    """A self-signed application certificate (DER) and its key (PEM), valid from
    ``valid[0]`` to ``valid[1]`` days from now."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import rsa
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    key = rsa.generate_private_key(public_exponent=65537, key_size=2048)
    subject = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)])
    now = datetime.datetime.now(datetime.UTC)
    cert = (x509.CertificateBuilder().subject_name(subject).issuer_name(subject)
            .public_key(key.public_key()).serial_number(x509.random_serial_number())
            .not_valid_before(now + datetime.timedelta(days=valid[0]))
            .not_valid_after(now + datetime.timedelta(days=valid[1]))
            .add_extension(x509.SubjectAlternativeName([
                x509.UniformResourceIdentifier(uri), x509.DNSName("localhost"),
                x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]), critical=False)
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .add_extension(x509.KeyUsage(
                digital_signature=True, content_commitment=True, key_encipherment=True,
                data_encipherment=True, key_agreement=False, key_cert_sign=False,
                crl_sign=False, encipher_only=False, decipher_only=False), critical=True)
            .add_extension(x509.ExtendedKeyUsage(
                [ExtendedKeyUsageOID.SERVER_AUTH if server else ExtendedKeyUsageOID.CLIENT_AUTH]),
                critical=False)
            .sign(key, hashes.SHA256()))
    cert_path, key_path = folder / f"{name}.der", folder / f"{name}-key.pem"
    cert_path.write_bytes(cert.public_bytes(serialization.Encoding.DER))
    key_path.write_bytes(key.private_bytes(serialization.Encoding.PEM,
                                           serialization.PrivateFormat.TraditionalOpenSSL,
                                           serialization.NoEncryption()))
    return cert_path, key_path


def test_a_plant_s_bridge_lets_only_its_users_measure(tmp_path: Path) -> None:
    """Basic256Sha256/SignAndEncrypt with a users file: an unencrypted client is refused,
    an anonymous session may read but not call Measure, a wrong password does not get a
    session; the configured user measures the rig's C."""
    server_cert, server_key = _certificate(tmp_path, "bridge", APPLICATION_URI, True)
    client_cert, client_key = _certificate(tmp_path, "plc", "urn:pneumatic-unload:test-client",
                                           False)
    trusted = tmp_path / "trusted"
    trusted.mkdir()
    (trusted / client_cert.name).write_bytes(client_cert.read_bytes())
    users = tmp_path / "users.txt"
    users.write_text(f"# the cell's PLC\nplc:{hash_password('s3cret')}\n")
    sec = {"certificate": str(client_cert), "private_key": str(client_key),
           "server_certificate": str(server_cert)}
    with _bench(tmp_path, "opcua_security_policy:=Basic256Sha256",
                f"opcua_certificate:={server_cert}", f"opcua_private_key:={server_key}",
                f"opcua_trusted_certs:={trusted}", f"opcua_users_file:={users}") as bench:

        async def main() -> None:
            async with _client(bench.url, **sec) as (_c, n):  # anonymous, encrypted
                await n.wait_state("ready")
                with pytest.raises(ua.uaerrors.BadUserAccessDenied):
                    await n.call("Measure", "part-F")
                with pytest.raises(ua.uaerrors.BadUserAccessDenied):
                    await n.call("StartMeasure", "part-F")
                assert await n.read("State") == "ready"  # nothing started
            with pytest.raises(ua.UaError):  # no encryption: no endpoint for it
                async with _client(bench.url, wait=0.0):
                    pass
            with pytest.raises(ua.uaerrors.BadUserAccessDenied):
                async with _client(bench.url, user="plc", password="wrong", retry=False,
                                   **sec):
                    pass
            async with _client(bench.url, user="plc", password="s3cret", **sec) as (_c, n):
                c, _b, _v = await _measure(n, "part-G")
                assert c == pytest.approx(TRUE_C, rel=0.02)

        _run(main())
        assert bench.alive()


def test_without_an_estimator_a_measurement_fails_cleanly_and_sigint_stops_a_call(
        tmp_path: Path) -> None:
    """The bridge alone: State 'no estimator'; Measure waits estimator_wait s for the
    estimator's action server, then answers BadNoCommunication with the reason; SIGINT
    while a measurement waits stops the node cleanly (exit 0)."""
    from pneumatic_unload.app.launch import NodeProcess

    port = _free_port()
    url = f"opc.tcp://127.0.0.1:{port}/pneumatic_unload/"
    node = NodeProcess("opcua", {"endpoint": url, "estimator_wait": 2.0,
                                 "allow_anonymous": True}, tmp_path,
                       env={**os.environ, "ROS_DOMAIN_ID": str(free_domain_id())})
    try:
        async def main() -> None:
            async with _client(url) as (_c, n):
                assert await n.read("State") == "no estimator"
                with pytest.raises(ua.uaerrors.BadNoCommunication):
                    await n.call("Measure", "part-H")
                assert "/estimator/measure is not available" in await n.read("Message")
                assert await n.read("State") == "no estimator"
                assert await n.read("MeasureDone") is True
                assert await n.call("StartMeasure", "part-I") is None
                assert await n.read("State") == "measuring"
                node.proc.send_signal(signal.SIGINT)  # while it waits for the estimator

        _run(main())
        assert node.stop() == 0, node.output()
    finally:
        node.stop()
    assert "Traceback" not in node.output()


# --------------------------------------------------------------------------- the core
def test_users_file_and_security_settings_are_checked(tmp_path: Path) -> None:
    """Passwords are kept as salted hashes; a users file or a security setting the bridge
    cannot run with is refused with the reason."""
    from pneumatic_unload.plc import Security, SecurityError, load_users
    from pneumatic_unload.plc.security import Users, check_password

    h = hash_password("s3cret")
    assert "s3cret" not in h and h != hash_password("s3cret")  # salted
    assert check_password("s3cret", h) and not check_password("s3cre", h)
    assert not check_password("s3cret", "md5$x")
    users = tmp_path / "users.txt"
    users.write_text(f"# plant\n\nplc:{h}\n")
    assert load_users(users) == {"plc": h}
    for text, why in [("plc:secret\n", "not 'name:pbkdf2_sha256"),
                      (f"plc:{h}\nplc:{h}\n", "given twice"), ("# nobody\n", "no user")]:
        users.write_text(text)
        with pytest.raises(SecurityError, match=why):
            load_users(users)
    cert = tmp_path / "c.der"
    cert.write_bytes(b"x")
    empty = tmp_path / "empty"
    empty.mkdir()
    for kwargs, why in [({"policy": "Basic128Rsa15"}, "must be one of"),
                        ({"policy": "Basic256Sha256"}, "needs the server's certificate"),
                        ({"policy": "Basic256Sha256", "certificate": str(cert),
                          "private_key": str(tmp_path / "none.pem")}, "no such file"),
                        ({"users": {"plc": h}}, "in clear"),
                        ({"policy": "Basic256Sha256", "certificate": str(cert),
                          "private_key": str(cert)}, "needs a trust list"),
                        ({"policy": "Basic256Sha256", "certificate": str(cert),
                          "private_key": str(cert), "trusted_certs": str(tmp_path / "none")},
                         "no such folder"),
                        ({"policy": "Basic256Sha256", "certificate": str(cert),
                          "private_key": str(cert), "trusted_certs": str(empty)},
                         "no certificate"),
                        ({"trusted_certs": str(empty)}, "need security_policy")]:
        with pytest.raises(SecurityError, match=why):
            Security(**kwargs)
    manager = Users({"plc": h})
    assert manager.get_user(None, "plc", "s3cret").name == "plc"
    assert manager.get_user(None, "plc", "wrong") is None
    assert manager.get_user(None, "nobody", "s3cret") is None
    assert manager.get_user(None).role.name == "Anonymous"  # may read, not call
    assert Users(None).get_user(None).role.name == "Anonymous"  # secure by default
    assert Users(None, allow_anonymous=True).get_user(None).role.name == "User"  # a lab bench


async def _stand_in(_part: str) -> Outcome:
    """A measurement without a rig (the in-process servers' tests)."""
    return Outcome("BadNoCommunication", "no rig here")


def _url() -> str:
    return f"opc.tcp://127.0.0.1:{_free_port()}/pneumatic_unload/"


@contextlib.asynccontextmanager
async def _server(url: str, security: Any, measure: Any = _stand_in
                  ) -> AsyncIterator[Any]:
    """A bridge server in this process (its event loop is the test's)."""
    from pneumatic_unload.plc import BridgeServer

    server = BridgeServer(url, measure, security)
    await server.start()
    try:
        yield server
    finally:
        await server.stop()


class _Plant:
    """A plant's certificates: the server's, a trusted client's, an untrusted one's, an
    expired and a not yet valid one (both in the trust folder), and a users file."""

    def __init__(self, tmp: Path) -> None:
        from pneumatic_unload.plc import Security

        uri = "urn:pneumatic-unload:test-client"
        self.server_cert, self.server_key = _certificate(tmp, "bridge", APPLICATION_URI, True)
        self.trusted = tmp / "trusted"
        self.trusted.mkdir()
        self.good = _certificate(tmp, "plc", uri, False)
        self.intruder = _certificate(tmp, "intruder", uri, False)
        self.expired = _certificate(tmp, "expired", uri, False, valid=(-30.0, -1.0))
        self.early = _certificate(tmp, "early", uri, False, valid=(1.0, 30.0))
        for cert, _key in (self.good, self.expired, self.early):  # certificates only
            (self.trusted / cert.name).write_bytes(cert.read_bytes())
        self.password = "s3cret"
        self.security = Security(
            policy="Basic256Sha256", certificate=str(self.server_cert),
            private_key=str(self.server_key), trusted_certs=str(self.trusted),
            users={"plc": hash_password(self.password)})

    def client(self, which: tuple[Path, Path] | None = None, **more: Any) -> dict[str, Any]:
        cert, key = which or self.good
        return {"certificate": str(cert), "private_key": str(key),
                "server_certificate": str(self.server_cert), "retry": False, **more}


def test_only_trusted_and_valid_client_certificates_get_a_session(tmp_path: Path) -> None:
    """Plant mode validates the client's certificate: a trusted one gets a session; an
    untrusted, an expired and a not yet valid one (the last two in the trust folder) are
    refused; so is a client whose secure channel uses an untrusted certificate while its
    CreateSession names the trusted one, or none (asyncua alone validates only the
    certificate the request names)."""
    plant = _Plant(tmp_path)
    url = _url()

    async def substituted(named: bytes | None) -> None:
        """The intruder's channel, its CreateSession naming ``named``."""
        c = Client(url, timeout=10)
        c.application_uri = "urn:pneumatic-unload:test-client"
        await c.set_security(SecurityPolicyBasic256Sha256, str(plant.intruder[0]),
                             str(plant.intruder[1]), server_certificate=str(plant.server_cert))
        create = c.uaclient.create_session

        async def create_naming(params: Any) -> Any:
            params.ClientCertificate = named
            return await create(params)

        c.uaclient.create_session = create_naming
        try:
            await c.connect()
        finally:
            with contextlib.suppress(Exception):
                await c.disconnect()

    async def main() -> None:
        async with _server(url, plant.security):
            async with _client(url, **plant.client()) as (_c, n):
                assert await n.read("State") == "no estimator"
                with pytest.raises(ua.uaerrors.BadUserAccessDenied):  # anonymous
                    await n.call("Measure", "part-J")
            for which, code in ((plant.intruder, ua.uaerrors.BadCertificateUntrusted),
                                (plant.expired, ua.uaerrors.BadCertificateTimeInvalid),
                                (plant.early, ua.uaerrors.BadCertificateTimeInvalid)):
                with pytest.raises(code):
                    async with _client(url, **plant.client(which)):
                        pass
            with pytest.raises(ua.uaerrors.BadCertificateInvalid):
                await substituted(plant.good[0].read_bytes())
            with pytest.raises(ua.uaerrors.BadCertificateUntrusted):
                await substituted(None)
            async with _client(url, **plant.client()) as (_c, n):  # still serving
                assert await n.read("State") == "no estimator"

    _run(main())


def test_results_go_bad_after_a_failed_measurement_and_the_table_is_the_server_s(
        ) -> None:
    """In process (a stand-in measurement): a good measurement's results read Good, a
    failed one's results read NaN/'' with the failure's code (not the previous part's C as
    Good); every row of :func:`address_space` resolves by its browse path on the server,
    and every node of the object is a row."""
    from pneumatic_unload.plc import Estimate, Security, address_space

    est = Estimate(unload_index=1, final=True, status="ok", status_text="a fine fit",
                   conductance=8e-9, conductance_std=1e-11, critical_ratio=0.4,
                   subsonic_index=0.5, tau_exp=2.0, verdict="pass", verdict_reason="in",
                   conductance_eq39=7.9e-9, p10=7e5, p_star=2.4e5, p_atm=101325.0)
    outcomes = [Outcome("Good", "ok", est), Outcome("BadDeviceFailure", "valve refused")]

    async def measure(_part: str) -> Outcome:
        return outcomes.pop(0)

    async def main() -> None:
        url = _url()
        async with _server(url, Security(allow_anonymous=True), measure) as server:
            await server.set_estimator(True)
            async with _client(url) as (c, n):
                dv = await n.node("Conductance").read_data_value(raise_on_bad_status=False)
                assert dv.StatusCode.name == "BadWaitingForInitialData"  # none yet
                assert await n.read("Ready") is True
                assert await _measure(n, "part-Q") == [8e-9, 0.4, "pass"]
                assert await n.read("ConductanceExpanded") == pytest.approx(2e-11)
                assert await n.read("ConductanceEq39") == 7.9e-9
                assert await n.read("VerdictReason") == "in"
                with pytest.raises(ua.uaerrors.BadDeviceFailure):
                    await _measure(n, "part-R")
                for name in ("Conductance", "ConductanceEq39", "CriticalRatio", "Verdict",
                             "Status", "InitialPressure"):
                    dv = await n.node(name).read_data_value(raise_on_bad_status=False)
                    assert dv.StatusCode.name == "BadDeviceFailure", name
                assert await n.read("Message") == "valve refused"
                assert await n.read("MeasurementCount") == 2
                assert (await n.read("Ready"), await n.read("State")) == (True, "ready")
                rows = address_space()
                for path, _kind, _unit, _doc in rows:
                    node = await c.nodes.objects.get_child(path.split("/"))
                    assert node.nodeid.NamespaceIndex == n.idx
                children = await n.obj.get_children()
                names = {(await ch.read_browse_name()).to_string() for ch in children}
                assert {f"2:OBJECT/{x}" for x in names} == {
                    p.replace("PneumaticUnload", "OBJECT", 1) for p, *_ in rows[1:]}

    _run(main())


def test_plant_mode_refuses_to_start_without_a_trust_list(tmp_path: Path) -> None:
    """Basic256Sha256 without trusted_certs: the node does not start (its reason on the
    console, exit 2), nor with its own certificate out of its validity dates."""
    from pneumatic_unload.app.launch import NodeProcess
    from pneumatic_unload.plc import Security, SecurityError

    plant = _Plant(tmp_path)
    with pytest.raises(SecurityError, match="needs a trust list"):
        Security(policy="Basic256Sha256", certificate=str(plant.server_cert),
                 private_key=str(plant.server_key))
    node = NodeProcess("opcua", {"endpoint": _url(), "security_policy": "Basic256Sha256",
                                 "certificate": str(plant.server_cert),
                                 "private_key": str(plant.server_key)}, tmp_path,
                       env={**os.environ, "ROS_DOMAIN_ID": str(free_domain_id())})
    try:
        node.proc.wait(timeout=60)
        assert node.proc.returncode == 2, node.output()  # a startup error
        assert "needs a trust list" in node.output()
        assert "Traceback" not in node.output()
    finally:
        node.stop()
    old_cert, old_key = _certificate(tmp_path, "old", APPLICATION_URI, True,
                                     valid=(-30.0, -1.0))

    async def main() -> None:
        with pytest.raises(SecurityError, match=r"valid from .* not now"):
            async with _server(_url(), Security(
                    policy="Basic256Sha256", certificate=str(old_cert),
                    private_key=str(old_key), trusted_certs=str(plant.trusted))):
                pass

    _run(main())


def test_secure_by_default_loopback_and_no_anonymous_calls() -> None:
    """The node's default endpoint and the launch file's bind loopback (the socket's
    address is 127.0.0.1); with the default security an anonymous session may read but
    its Measure and StartMeasure are refused (BadUserAccessDenied) and nothing is
    measured; with allow_anonymous (a lab bench) the measurement is called."""
    from pneumatic_unload.app.launch import load_launch
    from pneumatic_unload.config.nodes import node_parameters
    from pneumatic_unload.plc import Security

    default = node_parameters("opcua")["endpoint"].default
    assert default.startswith("opc.tcp://127.0.0.1:")
    assert not node_parameters("opcua")["allow_anonymous"].default
    launched = {n["name"]: n for n in load_launch(LAUNCH)}["opcua"]["params"]
    assert launched["endpoint"] == default and launched["allow_anonymous"] is False
    calls: list[str] = []

    async def counted(part: str) -> Outcome:
        calls.append(part)
        return Outcome("BadNoCommunication", "no rig here")

    async def main() -> None:
        async with _server(default.replace(":4840/", ":0/"), Security(), counted) as server:
            sockets = server.server.bserver._server.sockets
            assert {s.getsockname()[0] for s in sockets} == {"127.0.0.1"}
            url = f"opc.tcp://127.0.0.1:{server.port}/pneumatic_unload/"
            async with _client(url) as (_c, n):
                assert await n.read("State") == "no estimator"  # reading is allowed
                for method in ("Measure", "StartMeasure"):
                    with pytest.raises(ua.uaerrors.BadUserAccessDenied):
                        await n.call(method, "part-K")
                assert await n.read("PartId") == ""
        assert calls == []
        async with _server(_url(), Security(allow_anonymous=True), counted) as server:
            url = f"opc.tcp://127.0.0.1:{server.port}/pneumatic_unload/"
            async with _client(url) as (_c, n):
                with pytest.raises(ua.uaerrors.BadNoCommunication):
                    await n.call("Measure", "part-L")
        assert calls == ["part-L"]

    _run(main())


def test_string_arguments_have_a_length_limit() -> None:
    """A PartId longer than MAX_STRING characters, or with a control character, is
    answered BadInvalidArgument and never measured; one of MAX_STRING is measured; a
    request above MAX_MESSAGE bytes (a 2 MB PartId) is refused by the transport and the
    bridge serves on."""
    from pneumatic_unload.plc import Security
    from pneumatic_unload.plc.security import MAX_MESSAGE, MAX_STRING

    calls: list[str] = []

    async def counted(part: str) -> Outcome:
        calls.append(part)
        return Outcome("BadNoCommunication", "no rig here")

    async def main() -> None:
        url = _url()
        async with _server(url, Security(allow_anonymous=True), counted):
            async with _client(url) as (_c, n):
                for part in ("x" * (MAX_STRING + 1), "part\nforged log line", "a\x00b"):
                    for method in ("Measure", "StartMeasure"):
                        with pytest.raises(ua.uaerrors.BadInvalidArgument):
                            await n.call(method, part)
                assert calls == []
                with pytest.raises(ua.uaerrors.BadNoCommunication):
                    await n.call("Measure", "x" * MAX_STRING)
                assert calls == ["x" * MAX_STRING]
            with contextlib.suppress(Exception):
                async with _client(url) as (_c, n):
                    with pytest.raises((ua.UaError, TimeoutError, OSError)):
                        await n.call("Measure", "x" * (2 * MAX_MESSAGE))
            assert len(calls) == 1
            async with _client(url) as (_c, n):  # serving on
                assert await n.read("State") == "no estimator"

    _run(main())


def test_logins_cost_the_same_for_known_and_unknown_users(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """An unknown user name is checked by the same PBKDF2 (SHA-256, as many iterations as
    the users' costliest hash) as a known one, compared in constant time."""
    import hashlib
    import hmac

    from pneumatic_unload.plc import security

    manager = security.Users({"plc": hash_password("s3cret"),
                              "op": hash_password("x", iterations=150_000)})
    seen: list[tuple[str, int]] = []
    compared: list[int] = []
    real, compare = hashlib.pbkdf2_hmac, hmac.compare_digest

    def spy(name: str, password: bytes, salt: bytes, iterations: int) -> bytes:
        seen.append((name, iterations))
        return real(name, password, salt, iterations)

    def spy_compare(a: Any, b: Any) -> bool:
        compared.append(len(a))
        return compare(a, b)

    monkeypatch.setattr(security.hashlib, "pbkdf2_hmac", spy)
    monkeypatch.setattr(security.hmac, "compare_digest", spy_compare)
    assert manager.get_user(None, "op", "wrong") is None
    assert manager.get_user(None, "nobody", "wrong") is None
    assert manager.get_user(None, "plc", "s3cret").name == "plc"
    assert seen == [("sha256", 150_000), ("sha256", 150_000),
                    ("sha256", security.ITERATIONS)]
    assert compared == [32, 32, 32]


def test_repeated_failures_from_a_peer_slow_down() -> None:
    """The delay before a peer's login: none for its first FREE_FAILURES failures in a
    row, then doubling up to BACKOFF_MAX; another peer is not delayed; a success resets
    the peer; failures are forgotten after BACKOFF_FORGET."""
    from pneumatic_unload.plc import security

    manager = security.Users({"plc": hash_password("s3cret", iterations=1)})
    waits: list[float] = []

    async def main() -> None:
        for _ in range(security.FREE_FAILURES + 5):
            waits.append(manager.delay("10.0.0.9"))
            rec = manager._peer("10.0.0.9")
            rec.failures += 1  # as a failed login counts it (without its wait)
            rec.last = time.monotonic()
        assert manager.delay("10.0.0.8") == 0.0
        assert manager.delay("10.0.0.9", time.monotonic() + security.BACKOFF_FORGET + 1) == 0
        manager._peer("10.0.0.7").failures = security.FREE_FAILURES
        manager._peer("10.0.0.7").last = time.monotonic()
        assert await manager.verify("10.0.0.7", "plc", "s3cret") is not None
        assert manager.delay("10.0.0.7") == 0.0

    _run(main())
    first = security.BACKOFF_FIRST
    assert waits == [0.0] * (security.FREE_FAILURES + 1) + [
        min(first * 2 ** k, security.BACKOFF_MAX) for k in range(4)]


def test_a_wrong_password_flood_leaves_the_loop_and_a_logged_in_session_alone(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """16 wrong-password logins at once (a plant's bridge, in this process): the
    passwords are hashed off the event loop (never in its thread), a logged-in session
    reads on through the flood (every read within a generous bound, far above a read's
    milliseconds and below the seconds of 16 hashes in a row) and stays connected, and
    the flooding peer is slowed down."""
    import hashlib
    import threading

    from pneumatic_unload.plc import security

    plant = _Plant(tmp_path)
    url = _url()
    threads: list[str] = []
    real = hashlib.pbkdf2_hmac

    def spy(*args: Any) -> bytes:
        threads.append(threading.current_thread().name)
        return real(*args)

    monkeypatch.setattr(security.hashlib, "pbkdf2_hmac", spy)
    loop_thread = threading.current_thread().name

    async def bad_login() -> BaseException | None:
        try:  # a short request timeout: the peer's later logins wait their backoff
            async with _client(url, timeout=3.0,
                               **plant.client(user="plc", password="wrong")):
                return None
        except Exception as exc:  # every refusal counts (a Bad status, a timeout)
            return exc

    async def main() -> None:
        async with _server(url, plant.security) as server:
            threads.clear()  # the server's start made its dummy hash: logins from here
            async with _client(url, **plant.client(user="plc", password=plant.password)
                               ) as (c, n):
                assert threads and loop_thread not in threads
                flood = asyncio.gather(*(bad_login() for _ in range(16)))
                worst, reads = 0.0, 0
                while not flood.done():
                    t0 = time.monotonic()
                    assert await n.read("State") == "no estimator"
                    worst, reads = max(worst, time.monotonic() - t0), reads + 1
                    await asyncio.sleep(0.05)
                refused = await flood
                assert all(r is not None for r in refused)  # no wrong password got in
                assert reads >= 5 and worst < 1.5, (reads, worst)
                assert c.uaclient.state == UaClientState.CONNECTED
                assert await n.read("State") == "no estimator"
            assert server._users is not None and server._users.delay("127.0.0.1") > 0.0
        assert len(threads) > 1 and loop_thread not in threads

    _run(main())
