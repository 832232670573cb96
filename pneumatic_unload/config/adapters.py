"""The only converters of settings: command-line options, ROS parameters and JSON.

Everything is generated from the fields' metadata (:mod:`pneumatic_unload.config.fields`),
so a field added to a settings class appears with its unit, range and meaning as an option
of ``pneumatic-unload``, as a ranged ROS parameter of the node that uses it, and in the JSON
stored in bags. ROS-free: the nodes turn :class:`ParameterSpec` into ParameterDescriptors.

Conventions: an option not given is None (the settings' or the bag's value is then used;
zero is a value, never "not given"); an optional number (None meaning "auto" or "equal to
T10") is a ROS parameter whose 0 means None, since ROS parameters cannot be null.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from dataclasses import dataclass
from typing import Any

from pneumatic_unload.config.fields import ConfigError


@dataclass(frozen=True)
class ParameterSpec:
    """One ROS parameter made from a settings field.

    Attributes
    ----------
    name : str
        Parameter (= field) name.
    kind : str
        'double', 'integer', 'string' or 'bool'.
    default : Any
        ROS default (0.0 for an optional number whose default is None).
    description : str
        Meaning, unit and range (and what 0 means for an optional number).
    lo, hi : float or None
        Range of a number.
    """

    name: str
    kind: str
    default: Any
    description: str
    lo: float | None = None
    hi: float | None = None


def _fields(cls: type, only: tuple[str, ...] | None, exclude: tuple[str, ...]
            ) -> list[dataclasses.Field[Any]]:
    fs = [f for f in dataclasses.fields(cls) if f.metadata.get("kind")]
    if only is not None:
        by = {f.name: f for f in fs}
        fs = [by[n] for n in only]
    return [f for f in fs if f.name not in exclude]


def _help(f: dataclasses.Field[Any]) -> str:
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
            parser.add_argument(flag, type=float, default=None, metavar="X", help=_help(f))
        elif kind == "integer":
            parser.add_argument(flag, type=int, default=None, metavar="N", help=_help(f))
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
