# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Bags of an uncalibrated rig: the transducer's volts on /tank/pressure_volts
(pneumatic_unload_msgs/Voltage) are analysed offline through signal_gain/signal_offset, as
the Pa of the same unload are; a bag of the older layout (volts in a FluidPressure on
/tank/pressure) reads as before."""

import json

import pytest

from pneumatic_unload.app.cli import main
from pneumatic_unload.io.bag import (
    MSGTYPE_VOLTAGE,
    TOPIC_PRESSURE,
    TOPIC_VOLTS,
    BagRecorder,
    bag_summary,
    read_config,
    read_pressure,
)
from pneumatic_unload.io.bag.cdr import encode_stamped_pair

ZERO, SENS = 0.5, 1e-5  # transducer zero [V] and sensitivity [V/Pa]
CALIBRATION = ("--signal-gain", str(1.0 / SENS), "--signal-offset", str(-ZERO / SENS))


def _run(capsys, *argv):
    code = main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.fixture(scope="module")
def bags(tmp_path_factory):
    """(Pa bag, volts bag, old-layout volts bag) of one simulated unload."""
    d = tmp_path_factory.mktemp("volts")
    sim = d / "sim"
    assert main(["simulate", "--out", str(sim), "--volume", "0.001", "--conductance", "5e-9",
                 "--seed", "3"]) == 0
    t_ns, p = read_pressure(sim)
    cfg = read_config(sim)
    out = {}
    for name in ("pa", "volts", "old"):
        with BagRecorder(d / name, config=cfg) as rec:
            if name == "pa":
                rec.write_pressures(t_ns, p)
            elif name == "volts":
                for t, v in zip(t_ns.tolist(), (ZERO + SENS * p).tolist(), strict=True):
                    rec.write_raw(TOPIC_VOLTS, MSGTYPE_VOLTAGE, t,
                                  encode_stamped_pair(t, v, 0.0, frame_id="tank"))
            else:
                rec.write_pressures(t_ns, ZERO + SENS * p)
        out[name] = d / name
    return out


def _conductances(capsys, bag, *extra):
    code, out, err = _run(capsys, "analyze", str(bag), "--json", *extra)
    assert code == 0, err
    return [u["conductance_model"] for u in json.loads(out)["unloads"]]


def test_volts_bag_has_its_own_topic_and_type(bags):
    topics = bag_summary(bags["volts"]).topics
    assert TOPIC_PRESSURE not in topics
    assert topics[TOPIC_VOLTS].msgtype == MSGTYPE_VOLTAGE
    _, v = read_pressure(bags["volts"], topic=TOPIC_VOLTS)
    assert v.max() == pytest.approx(ZERO + SENS * read_pressure(bags["pa"])[1].max())


def test_volts_bag_analysed_offline_like_the_pa_bag(bags, capsys):
    ref = _conductances(capsys, bags["pa"])
    assert ref and ref[0] == pytest.approx(5e-9, rel=0.05)
    assert _conductances(capsys, bags["volts"], *CALIBRATION) == pytest.approx(ref, rel=1e-6)
    # the older layout: the same volts in a FluidPressure on /tank/pressure
    assert _conductances(capsys, bags["old"], *CALIBRATION) == pytest.approx(ref, rel=1e-6)


def test_volts_bag_without_calibration_is_a_clear_error(bags, capsys):
    code, out, err = _run(capsys, "analyze", str(bags["volts"]), "--json")
    assert code != 0 and not out
    assert "volts" in err and "--signal-gain" in err and "Traceback" not in err

