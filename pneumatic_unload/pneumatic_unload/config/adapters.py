# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""The only converters of settings: command-line options, ROS parameters and JSON.

Everything is generated from the fields' metadata (:mod:`pneumatic_unload.config.fields`),
so a field added to a settings class appears with its unit, range and meaning as an option
of ``pneumatic-unload``, as a ranged ROS parameter of the node that uses it, and in the JSON
stored in bags. ROS-free: the nodes turn :class:`ParameterSpec` into ParameterDescriptors.

Conventions: an option not given is None (the settings' or the bag's value is then used;
zero is a value, never "not given"); an optional number (None meaning "auto" or "equal to
T10") is a ROS parameter whose 0 means None, since ROS parameters cannot be null.

Command-line numbers accept a unit suffix, case-insensitive (``16.18L``, ``2dm3``, ``25C``,
``101.5kPa``, ``7bar``, ``100psi``, ``5e-9m3/(s Pa)``; a bare number is SI), are checked
against the field's range when parsed (argparse exits 2 with one line), and a bare number
out of range that is in range in a usual other unit is answered with "did you mean ...".
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from pneumatic_unload.config.fields import ConfigError, check_value

#: Unit suffixes accepted on the command line, per SI unit of a field: suffix -> (scale,
#: offset), SI value = scale * x + offset. Matched case-insensitively, ignoring spaces and
#: '^' ("16.18l", "5e-9 m^3/(s Pa)").
_PSI = 6894.757293168361
UNIT_SUFFIXES: dict[str, dict[str, tuple[float, float]]] = {
    "m^3": {"m3": (1.0, 0.0), "L": (1e-3, 0.0), "dm3": (1e-3, 0.0), "cm3": (1e-6, 0.0),
            "mL": (1e-6, 0.0)},
    "K": {"K": (1.0, 0.0), "C": (1.0, 273.15), "degC": (1.0, 273.15)},
    "Pa": {"Pa": (1.0, 0.0), "hPa": (1e2, 0.0), "mbar": (1e2, 0.0), "kPa": (1e3, 0.0),
           "bar": (1e5, 0.0), "MPa": (1e6, 0.0), "psi": (_PSI, 0.0)},
    "m^3/(s Pa)": {"m3/(s Pa)": (1.0, 0.0), "dm3/(s bar)": (1e-8, 0.0),
                   "L/(s bar)": (1e-8, 0.0)},
    "kg/(s Pa)": {"kg/(s Pa)": (1.0, 0.0)},
    "s": {"s": (1.0, 0.0), "ms": (1e-3, 0.0), "min": (60.0, 0.0)},
    "Hz": {"Hz": (1.0, 0.0), "kHz": (1e3, 0.0)},
}

#: The usual other units a bare number may have been meant in, per SI unit (in the order
#: suggested): (how to name it, suffix to write).
SUGGESTED_UNITS: dict[str, tuple[tuple[str, str], ...]] = {
    "m^3": (("L", "L"),),
    "K": (("degC", "C"),),
    "Pa": (("kPa", "kPa"), ("bar", "bar"), ("MPa", "MPa")),
    "m^3/(s Pa)": (("dm^3/(s bar)", "dm3/(s bar)"),),
}

_NUMBER = re.compile(r"\s*([-+]?(?:(?:\d+\.?\d*|\.\d+)(?:e[-+]?\d+)?|inf(?:inity)?|nan))"
                     r"\s*(.*?)\s*", re.IGNORECASE)


def _norm_unit(u: str) -> str:
    return re.sub(r"[\s^*·]", "", u).lower()


def parse_quantity(text: str, unit: str) -> tuple[float, bool]:
    """A number with an optional unit suffix, in the SI ``unit`` of a field.

    Parameters
    ----------
    text : str
        E.g. ``"16.18L"``, ``"25 degC"``, ``"7bar"`` or a bare ``"0.01618"`` (SI).
    unit : str
        SI unit of the field (``"m^3"``, ``"K"``, ``"Pa"``...).

    Returns
    -------
    value : float
        The value in ``unit``.
    bare : bool
        True when no suffix was written.

    Raises
    ------
    ValueError
        Not a number, or a suffix that is not a unit of this field.
    """
    m = _NUMBER.fullmatch(text)
    if m is None:
        raise ValueError(f"{text!r} is not a number")
    x = float(m.group(1))
    suffix = _norm_unit(m.group(2))
    if not suffix:
        return x, True
    table = {_norm_unit(k): v for k, v in UNIT_SUFFIXES.get(unit, {}).items()}
    if unit and unit != "-" and suffix == _norm_unit(unit):
        return x, False
    if suffix not in table:
        known = [unit, *UNIT_SUFFIXES.get(unit, {})] if unit and unit != "-" else []
        hint = f"; units of this option: {', '.join(dict.fromkeys(known))}" if known \
            else "; this option takes a plain number"
        raise ValueError(f"{text!r}: unknown unit {m.group(2)!r}{hint}")
    scale, offset = table[suffix]
    return scale * x + offset, False


def _did_you_mean(f: dataclasses.Field[Any], x: float) -> str:
    """'; did you mean ...' when the bare number ``x`` fits in a usual other unit."""
    md = f.metadata
    if not math.isfinite(x):
        return ""
    hints = []
    for name, suffix in SUGGESTED_UNITS.get(md.get("unit", ""), ()):
        scale, offset = UNIT_SUFFIXES[md["unit"]][suffix]
        v = scale * x + offset
        if md["min"] <= v <= md["max"]:
            # argparse takes "-5C" for an option: a negative value needs "--name=-5C"
            write = f"{x:g}{suffix}" if x >= 0 else \
                f"--{f.name.replace('_', '-')}={x:g}{suffix}"
            hints.append(f"{x:g} {name} = {v:g} {md['unit']}? (write {write})")
    return "; did you mean " + " or ".join(hints) if hints else ""


def option_type(f: dataclasses.Field[Any]) -> Callable[[str], Any]:
    """The argparse ``type=`` of a numeric field: unit suffixes, range check, hints.

    The returned function turns the option's text into the field's SI value and raises
    :class:`argparse.ArgumentTypeError` (one line: argparse exits 2) for a value that is not
    a number, not finite or outside the field's range, adding "did you mean 16.18 L = 0.01618
    m^3? (write 16.18L)" when a bare number would be in range in a usual other unit.
    """
    md = f.metadata

    def convert(text: str) -> Any:
        try:
            x, bare = parse_quantity(text, md.get("unit", ""))
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from exc
        if md["kind"] == "integer":
            if not math.isfinite(x) or int(x) != x:
                raise argparse.ArgumentTypeError(f"{f.name} must be an integer, got {text!r}")
            x = int(x)
        try:
            return check_value(f, x)
        except ConfigError as exc:
            raise argparse.ArgumentTypeError(
                str(exc) + (_did_you_mean(f, x) if bare else "")) from exc

    convert.__name__ = f.name  # argparse names the type in its own messages
    return convert


def field_of(cls: type, name: str) -> dataclasses.Field[Any]:
    """The dataclass field ``name`` of ``cls`` (for :func:`option_type`)."""
    return {f.name: f for f in dataclasses.fields(cls)}[name]


@dataclass(frozen=True)
class ParameterSpec:
    """One ROS parameter made from a settings field.

    Attributes
    ----------
    name : str
        Parameter (= field) name.
    kind : str
        'double', 'integer', 'string', 'bool' or 'string_array'.
    default : Any
        ROS default (0.0 for an optional number whose default is None; None for an unset
        string array).
    description : str
        Meaning, unit and range (and what 0 means for an optional number).
    lo, hi : float or None
        Range of a number.
    dynamic_typing : bool
        The parameter also takes another type (an integer for a double).
    choices : tuple of str
        The values a string parameter takes (empty: any).
    """

    name: str
    kind: str
    default: Any
    description: str
    lo: float | None = None
    hi: float | None = None
    dynamic_typing: bool = False
    choices: tuple[str, ...] = ()


def _fields(cls: type, only: tuple[str, ...] | None, exclude: tuple[str, ...]
            ) -> list[dataclasses.Field[Any]]:
    fs = [f for f in dataclasses.fields(cls) if f.metadata.get("kind")]
    if only is not None:
        by = {f.name: f for f in fs}
        fs = [by[n] for n in only]
    return [f for f in fs if f.name not in exclude]


def _help(f: dataclasses.Field[Any]) -> str:
    """argparse help of a field (its '%' escaped: argparse %-formats help strings)."""
    return _help_text(f).replace("%", "%%")


def _help_text(f: dataclasses.Field[Any]) -> str:
    md = f.metadata
    unit = f" [{md['unit']}]" if md.get("unit") and md["unit"] != "-" else ""
    if md["kind"] in ("number", "optional", "integer"):
        rng = f", range [{md['min']:g}, {md['max']:g}]"
        dflt = f.default
        if md["kind"] == "optional":
            return (f"{md['doc']}{unit}{rng}; not given: "
                    f"{md['none'] if dflt is None else f'{dflt:g}'}")
        return f"{md['doc']}{unit}{rng}, default {dflt:g}"
    if md["kind"] in ("choice", "names"):
        return f"{md['doc']} (from {', '.join(md['choices'])}), default {f.default!r}"
    return f"{md['doc']}, default {f.default}"


def add_options(parser: argparse.ArgumentParser, cls: type, *,
                only: tuple[str, ...] | None = None, exclude: tuple[str, ...] = ()) -> None:
    """One ``--name-with-dashes`` option per metadata field of ``cls`` (default None).

    Numbers take a unit suffix and are range-checked when parsed (:func:`option_type`).

    Parameters
    ----------
    parser : argparse.ArgumentParser
        Parser (or group) to add to.
    cls : type
        Settings dataclass.
    only, exclude : tuple of str
        Fields to include (in this order) or leave out.
    """
    for f in _fields(cls, only, exclude):
        md = f.metadata
        flag = "--" + f.name.replace("_", "-")
        kind = md["kind"]
        if kind in ("number", "optional"):
            parser.add_argument(flag, type=option_type(f), default=None, metavar="X",
                                help=_help(f))
        elif kind == "integer":
            parser.add_argument(flag, type=option_type(f), default=None, metavar="N",
                                help=_help(f))
        elif kind == "choice":
            parser.add_argument(flag, default=None, choices=md["choices"], help=_help(f))
        elif kind == "names":
            parser.add_argument(flag, default=None, metavar="A,B", help=_help(f))
        elif kind == "flag":
            parser.add_argument(flag, default=None, action=argparse.BooleanOptionalAction,
                                help=_help(f))


def given_options(args: argparse.Namespace, cls: type, *,
                  only: tuple[str, ...] | None = None, exclude: tuple[str, ...] = ()
                  ) -> dict[str, Any]:
    """The options of :func:`add_options` that were given, as field values [SI]."""
    out = {}
    for f in _fields(cls, only, exclude):
        v = getattr(args, f.name, None)
        if v is not None:
            out[f.name] = v
    return out


def parameter_specs(cls: type, *, only: tuple[str, ...] | None = None,
                    exclude: tuple[str, ...] = (), defaults: Any = None
                    ) -> dict[str, ParameterSpec]:
    """ROS parameter specs of the metadata fields of ``cls``.

    Parameters
    ----------
    cls : type
        Settings dataclass.
    only, exclude : tuple of str
        Fields to include or leave out.
    defaults : object, optional
        An instance whose values are the defaults (else the class defaults).
    """
    out = {}
    for f in _fields(cls, only, exclude):
        md = f.metadata
        kind = md["kind"]
        dflt = getattr(defaults, f.name) if defaults is not None else f.default
        unit = f" [{md['unit']}]" if md.get("unit") and md["unit"] != "-" else ""
        if kind in ("number", "optional"):
            lo, hi = float(md["min"]), float(md["max"])
            desc = f"{md['doc']}{unit}, range [{lo:g}, {hi:g}]"
            if kind == "optional":
                desc += f"; 0: {md['none']}"
                lo = min(lo, 0.0)
                dflt = 0.0 if dflt is None else dflt
            out[f.name] = ParameterSpec(f.name, "double", float(dflt), desc, lo, hi)
        elif kind == "integer":
            out[f.name] = ParameterSpec(f.name, "integer", int(dflt),
                                        f"{md['doc']}{unit}, range [{md['min']}, {md['max']}]",
                                        md["min"], md["max"])
        elif kind in ("choice", "names"):
            val = ",".join(dflt) if kind == "names" else dflt
            out[f.name] = ParameterSpec(
                f.name, "string", val, f"{md['doc']} (from {', '.join(md['choices'])}"
                + (", comma-separated)" if kind == "names" else ")"))
        elif kind == "flag":
            out[f.name] = ParameterSpec(f.name, "bool", bool(dflt), md["doc"])
    return out


def from_parameters(cls: type, values: dict[str, Any]) -> dict[str, Any]:
    """Field values [SI] from ROS parameter values (0 of an optional number: None)."""
    out = {}
    for f in _fields(cls, None, ()):
        if f.name not in values:
            continue
        v = values[f.name]
        if f.metadata["kind"] == "optional" and v == 0:
            v = None
        out[f.name] = v
    return out


def to_json(obj: Any) -> str:
    """JSON text of a settings dataclass (tuples as lists, keys sorted)."""
    d = dataclasses.asdict(obj)
    d = {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}
    return json.dumps(d, sort_keys=True)


def from_mapping(cls: type, d: dict[str, Any], *, strict: bool = True) -> dict[str, Any]:
    """Field values of ``cls`` from a mapping (bag JSON); unknown keys are an error when
    ``strict``."""
    known = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(d) - known)
    if unknown and strict:
        raise ConfigError(f"unknown {cls.__name__} key(s): {', '.join(unknown)}")
    return {k: v for k, v in d.items() if k in known}


#: The atmosphere added to gauge readings when none is given (``--gauge --atmosphere-auto``:
#: the record's final plateau is the zero, p_atm is fitted from it) [Pa absolute].
STANDARD_ATMOSPHERE = 101_325.0
#: The standard uncertainty of that assumed barometer [Pa]: the weather's spread at a bench
#: up to about 200 m above sea level (give the barometer's reading, ``--atmosphere PA``,
#: above that); it enters C's budget as the transducer's common offset does.
ASSUMED_BAROMETER_STD = 2_000.0


def gauge_inputs(gauge: bool, atmosphere: float | None, auto: bool,
                 settings: dict[str, Any]) -> float | None:
    """The atmosphere [Pa] to add to gauge readings, and ``settings`` completed, for gauge
    readings (``gauge``) with a barometer reading ``atmosphere`` [Pa] or none; ``auto``:
    p_atm fitted from the final plateau (set in ``settings`` as None). Without a barometer,
    auto takes :data:`STANDARD_ATMOSPHERE` and, unless given, a pressure uncertainty of
    :data:`ASSUMED_BAROMETER_STD`. Raises :class:`ConfigError` for gauge readings with
    neither. None when the readings are absolute."""
    if auto:
        settings["atmosphere"] = None
    if not gauge:
        return None
    if atmosphere is not None:
        return float(atmosphere)
    if not auto:
        raise ConfigError("--gauge needs --atmosphere PA (the barometer's reading), or "
                          "--atmosphere-auto (the final plateau is the zero; 101325 Pa "
                          f"+- {ASSUMED_BAROMETER_STD:g} assumed)")
    if settings.get("pressure_uncertainty") is None:
        settings["pressure_uncertainty"] = ASSUMED_BAROMETER_STD
    return STANDARD_ATMOSPHERE
