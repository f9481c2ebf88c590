"""The validated configuration base: fields that carry their range, unit and source.

Every number of the simulation lives in frozen dataclasses built from :func:`param` fields and
checked in ``__post_init__``; each field declares its unit, its allowed range and where its
default comes from:

* ``reference §n``: the reference system (``docs/reference.md``);
* ``datasheet``: public figures of a part (e.g. the Intel RealSense D435i);
* ``choice: ...``: the sources are silent; the reason for the value is given.

A wrong value raises ``ValueError`` naming the field, the value and the allowed range (the
message comes from :mod:`follow_env.sim.checks`), e.g. ``MotorConfig.time_constant_s=-1.0 is out
of range: must be in (0, 2] s``. numpy scalars are accepted and stored as Python numbers.

:class:`Sections` is the base of a whole configuration tree: a frozen dataclass whose fields are
sections, with ``from_overrides`` mapping ``gym.make`` keyword arguments onto it.
"""

from __future__ import annotations

import dataclasses
import functools
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

from follow_env.sim.checks import as_number, check_number, out_of_range, range_text

__all__ = ["Sections", "Validated", "field_spec", "param"]


def param(
    default: float | int | str | None,
    lo: float | None = None,
    hi: float | None = None,
    unit: str = "",
    doc: str = "",
    *,
    lo_open: bool = False,
    integer: bool = False,
    choices: tuple[str, ...] | None = None,
    optional: bool = False,
) -> Any:
    """A dataclass field carrying its range, unit and documentation as metadata.

    :param default: the default value.
    :param lo: lowest allowed value (``None``: unbounded).
    :param hi: highest allowed value, inclusive (``None``: unbounded).
    :param unit: the unit, e.g. ``"m"``, ``"rad/s"``, ``"%"``.
    :param doc: where the default comes from.
    :param lo_open: ``lo`` itself is excluded.
    :param integer: the value must be an integer.
    :param choices: for string fields, the allowed values (``None``: free-form text, checked
        by whoever uses it, e.g. a registry name).
    :param optional: ``None`` is allowed too.
    """
    meta = {
        "lo": lo,
        "hi": hi,
        "unit": unit,
        "doc": doc,
        "lo_open": lo_open,
        "integer": integer,
        "choices": choices,
        "optional": optional,
    }
    return field(default=default, metadata=meta)


def field_spec(cls: type, name: str) -> Mapping[str, Any]:
    """The range metadata of field ``name`` of config class ``cls`` (used by tests and docs)."""
    return next(f.metadata for f in dataclasses.fields(cls) if f.name == name)


def rule_text(meta: Mapping[str, Any]) -> str:
    """What a field allows, in words (for messages and docs)."""
    if meta["choices"] is not None:
        return "one of " + ", ".join(repr(c) for c in meta["choices"])
    return range_text(
        meta["lo"], meta["hi"], unit=meta["unit"], lo_open=meta["lo_open"], integer=meta["integer"]
    )


def _check_field(owner: object, f: dataclasses.Field[Any], value: object) -> object:
    meta = f.metadata
    where = f"{type(owner).__name__}.{f.name}"
    if meta["optional"] and value is None:
        return None
    if meta["choices"] is not None:
        if value not in meta["choices"]:
            raise out_of_range(where, value, rule_text(meta))
        return value
    if isinstance(f.default, str):
        if not isinstance(value, str):
            raise out_of_range(where, value, "a string")
        return value  # free-form text (e.g. a registry name): checked by whoever uses it
    return check_number(
        where,
        value,
        meta["lo"],
        meta["hi"],
        unit=meta["unit"],
        lo_open=meta["lo_open"],
        integer=meta["integer"],
        optional=meta["optional"],
    )


class Validated:
    """Mixin for config sections: every :func:`param` field is checked after construction, and
    numpy scalars are stored as Python numbers."""

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):  # type: ignore[arg-type]
            if "lo" not in f.metadata:
                continue
            value = getattr(self, f.name)
            checked = _check_field(self, f, value)
            if checked is not value:
                object.__setattr__(self, f.name, as_number(checked))

    @classmethod
    def describe(cls) -> list[tuple[str, Any, str, str, str]]:
        """``(field, default, unit, allowed, source)`` for every field (docs and tests)."""
        rows = []
        for f in dataclasses.fields(cls):  # type: ignore[arg-type]
            if "lo" in f.metadata:
                meta = f.metadata
                rows.append((f.name, f.default, meta["unit"], rule_text(meta), meta["doc"]))
        return rows


@functools.cache
def _section_types(cls: type) -> dict[str, type]:
    """Declared type of every section field (string annotations resolved)."""
    return typing.get_type_hints(cls)


@dataclass(frozen=True)
class Sections:
    """Base of a configuration tree: every field is a section (a :class:`Validated` dataclass
    or another :class:`Sections`).

    ``NESTED`` names a field whose own sections may also be given at the top level: the
    platform's sections (``robot``, ``motor``, ...) are reached as ``robot={...}`` as well as
    ``platform={"robot": {...}}``, and read as ``cfg.robot`` as well as ``cfg.platform.robot``.
    """

    NESTED: ClassVar[str | None] = None

    def __post_init__(self) -> None:
        for name, kind in _section_types(type(self)).items():
            if name not in self.section_names():
                continue
            value = getattr(self, name)
            if not isinstance(value, kind):
                raise out_of_range(f"{type(self).__name__}.{name}", value, f"a {kind.__name__}")

    def __getattr__(self, name: str) -> Any:
        # Only reached for names that are not fields: the nested tree's sections.
        nested = type(self).NESTED
        if nested is not None and not name.startswith("_"):
            inner = object.__getattribute__(self, nested)
            if name in inner.section_names():
                return getattr(inner, name)
        raise AttributeError(f"{type(self).__name__} has no section {name!r}")

    @classmethod
    def section_names(cls) -> tuple[str, ...]:
        """The section fields of this tree, in order."""
        return tuple(f.name for f in dataclasses.fields(cls))

    def sections(self) -> dict[str, Any]:
        """Section name -> its current value."""
        return {name: getattr(self, name) for name in self.section_names()}

    def leaf_sections(self) -> dict[str, Any]:
        """Every section holding fields, by the name users give it (a nested tree's sections
        under their own names, e.g. ``robot`` for ``platform.robot``)."""
        out: dict[str, Any] = {}
        for name, value in self.sections().items():
            if isinstance(value, Sections):
                out.update(value.leaf_sections())
            else:
                out[name] = value
        return out

    def replace(self, **sections: Any) -> Any:
        """A copy with whole sections replaced or updated from mappings of field values."""
        return type(self).from_overrides(self, sections)

    @classmethod
    def from_overrides(cls, base: Any, overrides: Mapping[str, Any]) -> Any:
        """Apply ``{"section": {"field": value} | SectionConfig}`` (or ``"section.field"``
        keys) to ``base``, in the order given. Unknown sections or fields raise ``ValueError``
        listing the known ones; values are validated by the sections themselves."""
        nested = cls.NESTED
        inner_names = getattr(base, nested).section_names() if nested else ()
        changes: dict[str, list[Any]] = {}
        for key, value in overrides.items():
            section, _, rest = key.partition(".")
            if section not in cls.section_names():
                if section not in inner_names:
                    known = ", ".join((*cls.section_names(), *inner_names))
                    raise ValueError(
                        f"unknown config section {section!r}: known sections are {known}"
                    )
                section, rest = nested, key  # type: ignore[assignment]
            changes.setdefault(section, []).append({rest: value} if rest else value)
        new: dict[str, Any] = {}
        for name in cls.section_names():
            current = getattr(base, name)
            for change in _merged(changes.get(name, ())):
                current = _apply(cls, name, current, change)
            new[name] = current
        return cls(**new)

    def to_dict(self) -> dict[str, Any]:
        """Plain nested dict (for run folders and reports); a nested tree with a ``NAME``
        (the platform) says which it is."""
        out: dict[str, Any] = {}
        for name, value in self.sections().items():
            if isinstance(value, Sections):
                inner = value.to_dict()
                out[name] = {"name": value.NAME, **inner} if hasattr(value, "NAME") else inner
            else:
                out[name] = dataclasses.asdict(value)
        return out


class _Changes(list[tuple[str, Any]]):
    """The items of several mappings of one section, in the order given (keys may repeat)."""

    def items(self) -> _Changes:
        return self


def _merged(changes: list[Any]) -> list[Any]:
    """A section's changes with each run of mappings made one: the section is then checked
    once, on all of its new values, so a check across fields (a gap smaller than the tile)
    does not depend on the order the fields were given in, nor name a field not given."""
    out: list[Any] = []
    for change in changes:
        if not isinstance(change, Mapping):
            out.append(change)  # a whole section object, or a value _apply refuses
        elif out and isinstance(out[-1], _Changes):
            out[-1].extend(change.items())
        else:
            out.append(_Changes(change.items()))
    return out


def _apply(cls: type, name: str, current: Any, change: Any) -> Any:
    """Section ``name`` (now ``current``) after one change: a whole section object, or a
    mapping of its fields (of its sections, for a nested tree; keys may be dotted)."""
    kind = _section_types(cls)[name]
    if isinstance(change, kind):
        return change
    where = f"{cls.__name__}.{name}"
    if not isinstance(change, (Mapping, _Changes)):
        what = "sections" if isinstance(current, Sections) else "fields"
        raise out_of_range(where, change, f"a {kind.__name__} or a mapping of its {what}")
    if isinstance(current, Sections):
        return type(current).from_overrides(current, change)
    known = {f.name for f in dataclasses.fields(current)}
    values: dict[str, Any] = {}
    for key, value in change.items():
        fname, dot, _ = key.partition(".")
        if dot or fname not in known:
            raise ValueError(
                f"unknown field {name}.{key}: {type(current).__name__} has "
                + ", ".join(sorted(known))
            )
        values[fname] = value
    return dataclasses.replace(current, **values)
