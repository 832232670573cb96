# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""Settings fields that carry their unit, bounds and meaning.

Every settings class of the package (the tank, the simulated rig, the estimator, the
discrepancy workflow) declares its fields with these helpers; ``field.metadata`` then holds
what :mod:`pneumatic_unload.config.adapters` needs to make command-line options, ROS
parameter descriptors and JSON, and what :func:`validate` checks. SI units.

Metadata keys: ``kind`` ('number', 'optional', 'integer', 'choice', 'flag', 'names'),
``unit``, ``min``, ``max``, ``doc``, ``choices``, ``none`` (what None means, for optional
numbers).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import field
from typing import Any


class ConfigError(ValueError):
    """A configuration value is out of range, of the wrong type or unknown."""


def number(default: float, unit: str, lo: float, hi: float, doc: str) -> Any:
    """A finite number in [lo, hi] [unit]."""
    return field(default=default, metadata={"kind": "number", "unit": unit, "min": lo,
                                            "max": hi, "doc": doc})


def optional(default: float | None, unit: str, lo: float, hi: float, doc: str,
             none: str) -> Any:
    """A number in [lo, hi] [unit], or None meaning ``none``."""
    return field(default=default, metadata={"kind": "optional", "unit": unit, "min": lo,
                                            "max": hi, "doc": doc, "none": none})


def integer(default: int, lo: int, hi: int, doc: str, unit: str = "") -> Any:
    """An integer in [lo, hi]."""
    return field(default=default, metadata={"kind": "integer", "unit": unit, "min": lo,
                                            "max": hi, "doc": doc})


def choice(default: str, choices: tuple[str, ...], doc: str) -> Any:
    """One of ``choices``."""
    return field(default=default, metadata={"kind": "choice", "unit": "",
                                            "choices": choices, "doc": doc})


def flag(default: bool, doc: str) -> Any:
    """A boolean."""
    return field(default=default, metadata={"kind": "flag", "unit": "", "doc": doc})


def names(default: tuple[str, ...], choices: tuple[str, ...], doc: str) -> Any:
    """A tuple of names from ``choices`` (a comma-separated string is accepted)."""
    return field(default=default, metadata={"kind": "names", "unit": "", "choices": choices,
                                            "doc": doc})


def parse_names(value: str | list[str] | tuple[str, ...]) -> tuple[str, ...]:
    """Names from a comma-separated string or a sequence ('' or 'none': none)."""
    if isinstance(value, str):
        items = [v.strip() for v in value.split(",")]
    else:
        try:
            items = [str(v).strip() for v in value]
        except TypeError:
            raise ConfigError(f"expected names as a comma-separated string or a list, got "
                              f"{value!r}") from None
    return tuple(v for v in items if v and v != "none")


def check_value(f: dataclasses.Field[Any], v: Any) -> Any:
    """Validate one field value against its metadata; return it normalised.

    Raises
    ------
    ConfigError
        With the field's name, unit, range and meaning.
    """
    md = f.metadata
    kind = md.get("kind")
    if kind is None:
        return v
    if kind == "names":
        v = parse_names(v)
        bad = [e for e in v if e not in md["choices"]]
        if bad:
            raise ConfigError(f"unknown {f.name} {bad}; known: {', '.join(md['choices'])}")
        return tuple(dict.fromkeys(v))
    if kind == "choice":
        if v not in md["choices"]:
            raise ConfigError(f"{f.name}={v!r} is not one of {md['choices']}")
        return v
    if kind == "flag":
        if not isinstance(v, bool):
            raise ConfigError(f"{f.name} must be true or false, got {v!r}")
        return v
    if kind == "optional" and v is None:
        return None
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ConfigError(f"{f.name} must be a number, got {v!r}")
    if type(v) is float and md["min"] <= v <= md["max"] and math.isfinite(v) \
            and kind != "integer":
        return v  # the common case (a fit's hot loop): finite and in range
    unit = f" {md['unit']}" if md.get("unit") and md["unit"] != "-" else ""
    if isinstance(v, int) and not -1e300 < v < 1e300:  # would overflow a float
        raise ConfigError(f"{f.name} (an integer of {v.bit_length()} bits){unit} is outside "
                          f"[{md['min']:g}, {md['max']:g}] ({md['doc']})")
    if not math.isfinite(v):
        raise ConfigError(f"{f.name}={v!r}{unit} is not a finite number (range "
                          f"[{md['min']:g}, {md['max']:g}]; {md['doc']})")
    if kind == "integer" and int(v) != v:
        raise ConfigError(f"{f.name} must be an integer, got {v!r}")
    if not md["min"] <= v <= md["max"]:
        raise ConfigError(f"{f.name}={v!r}{unit} is outside [{md['min']:g}, {md['max']:g}]"
                          f" ({md['doc']})")
    return int(v) if kind == "integer" else v


def validate(obj: Any) -> None:
    """Validate (and normalise in place) every metadata field of a frozen dataclass.

    Raises
    ------
    ConfigError
        The first field out of range, of the wrong type or unknown.
    """
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        nv = check_value(f, v)
        if nv is not v:
            object.__setattr__(obj, f.name, nv)


@functools.cache
def _fields_by_name(cls: type) -> dict[str, dataclasses.Field[Any]]:
    """The dataclass fields of ``cls`` by name (computed once per class)."""
    return {f.name: f for f in dataclasses.fields(cls)}


def with_changes(obj: Any, changes: dict[str, Any]) -> Any:
    """A copy of a validated frozen dataclass with ``changes``, checking only those fields.

    The fast twin of :func:`dataclasses.replace` for hot loops (a fit builds a configuration
    per model evaluation): the changed values are range-checked and normalised by
    :func:`check_value` exactly as :func:`validate` would; ``__post_init__`` is not run, so
    use it only where no cross-field rule can change (the fields named do not take part in
    one).

    Raises
    ------
    ConfigError
        A changed value out of range, of the wrong type, or an unknown field.
    """
    fields = _fields_by_name(type(obj))
    new = object.__new__(type(obj))  # a shallow copy (copy.copy's reduce protocol is slow)
    new.__dict__.update(obj.__dict__)
    for name, v in changes.items():
        f = fields.get(name)
        if f is None:
            raise ConfigError(f"unknown field {name!r} of {type(obj).__name__}")
        object.__setattr__(new, name, check_value(f, v))
    return new


def describe(cls: type) -> list[dict[str, Any]]:
    """One dict per field: name, default, kind, unit, min/max or choices, doc."""
    return [{"name": f.name, "default": f.default, **f.metadata}
            for f in dataclasses.fields(cls) if f.metadata.get("kind")]
