# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Settings declared once: the tank and gas type, the adapters, the gas carried everywhere."""

import argparse
import dataclasses
import json

import pytest
import yaml

from pneumatic_unload.app.cli import build_parser, main
from pneumatic_unload.config import TANK_FIELDS, ConfigError, RigConfig, TankSpec, adapters
from pneumatic_unload.discrepancy import DiscrepancyError, DiscrepancySettings
from pneumatic_unload.estimation import EstimationError, EstimatorSettings

SETTINGS = (RigConfig, EstimatorSettings, DiscrepancySettings)
CO2 = {"gas_constant": 188.92, "gamma": 1.289}


@pytest.mark.parametrize("cls", SETTINGS)
def test_every_settings_class_embeds_the_one_tank_declaration(cls):
    assert issubclass(cls, TankSpec)
    mine = {f.name: f for f in dataclasses.fields(cls)}
    for f in dataclasses.fields(TankSpec):
        assert f.name in TANK_FIELDS
        # RigConfig alone needs a number for p_atm (a simulated atmosphere), same field
        assert mine[f.name].metadata == f.metadata
        assert mine[f.name].default == f.default


@pytest.mark.parametrize("cls,err", [(EstimatorSettings, EstimationError),
                                     (DiscrepancySettings, DiscrepancyError),
                                     (TankSpec, ConfigError)])
def test_ranges_come_from_the_metadata(cls, err):
    with pytest.raises(err, match=r"volume=1000000000.0 m\^3 is outside"):
        cls(volume=1e9)
    with pytest.raises(err, match="initial_temperature"):
        cls(initial_temperature=-5.0)
    with pytest.raises(err, match="gamma"):
        cls(gamma=float("inf"))
    assert cls(volume=2e-3, atmosphere=None, wall_temperature=None).wall == 293.15


def test_cli_options_are_generated_from_the_fields():
    sub = build_parser()._subparsers._group_actions[0].choices
    analyze = {a.dest for a in sub["analyze"]._actions}
    for f in dataclasses.fields(EstimatorSettings):
        assert f.name in analyze, f.name
    simulate = {a.dest for a in sub["simulate"]._actions}
    assert {f.name for f in dataclasses.fields(RigConfig)} <= simulate
    disc = {a.dest for a in sub["discrepancy"]._actions}
    assert set(TANK_FIELDS) <= disc
    ns = argparse.Namespace(volume=0.0, gamma=None)
    # zero is a value, never "not given"
    assert adapters.given_options(ns, TankSpec) == {"volume": 0.0}


def test_ros_parameters_round_trip_and_optional_zero_means_none():
    specs = adapters.parameter_specs(EstimatorSettings)
    assert set(specs) == {f.name for f in dataclasses.fields(EstimatorSettings)}
    assert specs["atmosphere"].kind == "double" and "0: from the final plateau" in \
        specs["atmosphere"].description
    assert specs["min_plateau"].kind == "integer" and specs["curve_fit"].kind == "bool"
    values = {n: s.default for n, s in specs.items()}
    values.update(atmosphere=0.0, gas_constant=CO2["gas_constant"])
    s = EstimatorSettings(**adapters.from_parameters(EstimatorSettings, values))
    assert s.atmosphere is None and s.wall_temperature is None
    assert s.gas.gas_constant == CO2["gas_constant"]
    back = EstimatorSettings(**adapters.from_mapping(EstimatorSettings,
                                                     json.loads(adapters.to_json(s))))
    assert back == s


@pytest.mark.parametrize("node,cls", [("estimator", EstimatorSettings),
                                      ("simulator", RigConfig)])
def test_node_yaml_lists_every_settings_parameter_with_its_default(repo_root, node, cls):
    params = yaml.safe_load((repo_root / "config" / f"{node}.yaml").read_text())
    params = params["/**"]["ros__parameters"]
    for name, spec in adapters.parameter_specs(cls).items():
        assert name in params, f"{node}.yaml lacks {name}"
        if cls is EstimatorSettings:
            assert params[name] == spec.default, name


def test_a_bag_of_another_gas_is_analysed_with_its_gas(tmp_path, capsys):
    """The bag holds only the rig configuration (no estimator settings): its gas must be
    used, not air's (a bug of the hand-written converter this replaced)."""
    bag = tmp_path / "co2"
    assert main(["simulate", "--out", str(bag), "--no-estimate", "--volume", "0.002",
                 "--conductance", "5e-9", "--gas-constant", str(CO2["gas_constant"]),
                 "--gamma", str(CO2["gamma"]), "--noise-std", "300"]) == 0
    capsys.readouterr()
    assert main(["analyze", str(bag), "--json", "--heat-model", "adiabatic"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["settings"]["gas_constant"] == CO2["gas_constant"]
    assert out["settings"]["gamma"] == CO2["gamma"]
    (u,) = out["unloads"]
    assert u["conductance_model"] == pytest.approx(5e-9, rel=0.005)
    # and the command line still wins over the bag
    assert main(["analyze", str(bag), "--json", "--gamma", "1.4"]) == 0
    assert json.loads(capsys.readouterr().out)["settings"]["gamma"] == 1.4


def test_estimator_node_declares_the_gas(repo_root):
    from pneumatic_unload.config.nodes import node_parameters

    params = node_parameters("estimator")
    assert {"gas_constant", "gamma"} <= set(params)
    assert set(adapters.parameter_specs(EstimatorSettings)) <= set(params)
    src = (repo_root / "pneumatic_unload/nodes/estimator.py").read_text()
    assert 'node_parameters("estimator")' in src
    assert "runs" not in {line.split()[1].split(".")[-1] for line in src.splitlines()
                          if line.startswith("from pneumatic_unload")}


