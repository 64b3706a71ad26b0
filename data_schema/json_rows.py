"""A JSON object as a frozen dataclass, so that each of its keys is spelled once: as a field.

A row of a document (:mod:`data_schema.metrics_doc`, :mod:`data_schema.intervals_doc`) is a
:class:`JsonRow` dataclass whose fields are its keys, in the order they are written;
:meth:`JsonRow.to_json` writes it (rows nested in it, in lists or in dicts, alike) and
:meth:`JsonRow.from_json` reads it back, so every other module reads ``row.ld_mean_mm``, never
a key. The checks read the type each key's value must have from the field's annotation
(:meth:`JsonRow.kinds`: a ``float`` is any JSON number, a row or dict an object, a list an
array, ``| None`` also null), so the tables they check against are the types themselves.

A field may be left out of a document in three ways, each said by its default:
:func:`written_if_set` (absent where it is None, never null: a value a row has only
sometimes), :func:`since_version` (absent from documents older than the field; written always,
null where None) and :func:`flattened` (a row of its own whose keys sit in the parent's
object, all absent where it is None).
"""

from __future__ import annotations

import types
from collections.abc import Mapping
from dataclasses import MISSING, Field, field, fields, is_dataclass
from typing import Any, Self, Union, cast, get_args, get_origin, get_type_hints

OMIT = "omit"          # metadata: written only where set (never null)
SINCE = "since"        # metadata: may be absent from an older document
FLAT = "flat"          # metadata: a row whose keys sit in the parent's object
KIND = "kind"          # metadata: the JSON type where the annotation says too little
NUMBER = (int, float)  # a JSON number: an integer or a fraction (a boolean is refused apart)

Kind = type | tuple[type, ...]


def written_if_set() -> Any:
    """A field absent from the object where it is None (never written as null)."""
    return field(default=None, metadata={OMIT: True})


def since_version() -> Any:
    """A field an older document lacks (read as None); written always, null where None."""
    return field(default=None, metadata={SINCE: True})


def flattened() -> Any:
    """A row whose keys are written into the parent's object; all absent where None."""
    return field(default=None, metadata={FLAT: True})


def strictly(kind: Kind) -> Any:
    """A required field whose JSON type is ``kind`` (a ``float`` that must be written as
    one, say), not what its annotation would give."""
    return field(metadata={KIND: kind})


class JsonRow:
    """A frozen dataclass written as, and read from, one JSON object (see the module)."""

    def to_json(self) -> dict[str, Any]:
        """The object: the fields in order, rows in them written in turn."""
        out: dict[str, Any] = {}
        for f in _fields(type(self)):
            value = getattr(self, f.name)
            if f.metadata.get(FLAT):
                out.update({} if value is None else value.to_json())
            elif not (value is None and f.metadata.get(OMIT)):
                out[f.name] = _plain(value)
        return out

    @classmethod
    def from_json(cls, obj: Mapping[str, Any]) -> Self:
        """The row of a checked object (keys it does not know are left aside)."""
        hints = get_type_hints(cls)
        values: dict[str, Any] = {}
        for f in _fields(cls):
            inner = _row_type(hints[f.name])
            if f.metadata.get(FLAT) and inner is not None:
                if any(key in obj for key in inner.keys()):
                    values[f.name] = inner.from_json(obj)
            elif f.name in obj:
                values[f.name] = _typed(hints[f.name], obj[f.name])
        return cls(**values)

    @classmethod
    def keys(cls) -> tuple[str, ...]:
        """Every key the object may have, in the order they are written."""
        hints = get_type_hints(cls)
        out: list[str] = []
        for f in _fields(cls):
            inner = _row_type(hints[f.name])
            out += inner.keys() if f.metadata.get(FLAT) and inner is not None else [f.name]
        return tuple(out)

    @classmethod
    def kinds(cls) -> dict[str, Kind]:
        """Each key's JSON type, for :func:`data_schema.json_docs.typed_keys`."""
        hints = get_type_hints(cls)
        out: dict[str, Kind] = {}
        for f in _fields(cls):
            inner = _row_type(hints[f.name])
            if f.metadata.get(FLAT) and inner is not None:
                out.update(inner.kinds())
            else:
                out[f.name] = f.metadata.get(KIND) or _kind(hints[f.name],
                                                           nullable=not f.metadata.get(OMIT))
        return out

    @classmethod
    def optional(cls) -> tuple[str, ...]:
        """The keys an object may lack (:func:`written_if_set`, :func:`since_version`, and
        the keys of a :func:`flattened` row)."""
        required = {f.name for f in _fields(cls) if f.default is MISSING
                    and f.default_factory is MISSING}
        return tuple(k for k in cls.keys() if k not in required)


def _fields(cls: type) -> tuple[Field, ...]:
    """A row's fields (every :class:`JsonRow` is a dataclass)."""
    return fields(cast(Any, cls))


def _plain(value: Any) -> Any:
    """A field's value as JSON: rows as objects, lists and dicts of them alike."""
    if isinstance(value, JsonRow):
        return value.to_json()
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


def _members(hint: Any) -> tuple[list[Any], bool]:
    """A union's members other than None, and whether None is one ([hint], False else)."""
    if get_origin(hint) in (Union, types.UnionType):
        args = get_args(hint)
        return [a for a in args if a is not type(None)], type(None) in args
    return [hint], False


def _row_type(hint: Any) -> type[JsonRow] | None:
    """The row a field holds (alone or with None), if it holds one."""
    members, _ = _members(hint)
    one = members[0] if len(members) == 1 else None
    return one if isinstance(one, type) and issubclass(one, JsonRow) else None


def _typed(hint: Any, value: Any) -> Any:
    """A JSON value as the annotation ``hint`` says: rows (in lists, dicts) read as rows."""
    if value is None:
        return None
    members, _ = _members(hint)
    if len(members) != 1:
        return value
    kind, args = members[0], get_args(members[0])
    if isinstance(kind, type) and issubclass(kind, JsonRow):
        return kind.from_json(value)
    if get_origin(kind) is dict and len(args) == 2:
        return {k: _typed(args[1], v) for k, v in value.items()}
    if get_origin(kind) is list and args:
        return [_typed(args[0], v) for v in value]
    return value


def _kind(hint: Any, nullable: bool) -> Kind:
    """The JSON type of an annotation: ``float`` any number, a row or dict an object, a list
    an array, ``| None`` (where ``nullable``) null too."""
    members, none = _members(hint)
    kinds: list[type] = []
    for member in members:
        origin = get_origin(member) or member
        if origin is float:
            kinds += NUMBER
        elif is_dataclass(origin):
            kinds.append(dict)
        else:
            kinds.append(origin)
    if none and nullable:
        kinds.append(type(None))
    return kinds[0] if len(kinds) == 1 else tuple(kinds)
