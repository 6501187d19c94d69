"""Config schemas as pydantic models: one place says each field's type, range and allowed keys;
:func:`validate` turns pydantic's errors into a :class:`jflex.ConfigError` naming the file and the
field (``datasets[1].split``) and what is expected, and :func:`markdown_table` renders the same
schema as the table the docs show.

A schema is a pydantic ``BaseModel`` built on :class:`Strict` (unknown keys refused, no string to
number coercion, NaN/inf refused). A field's ``json_schema_extra={"expects": ...}`` overrides the
type description derived from its annotation; a custom check raises
``PydanticCustomError(kind, message, {"at": key})`` to name a key below the field it checks.
"""

from __future__ import annotations

import os
import types
import typing
from typing import Any, Literal

import annotated_types as at
from pydantic import BaseModel, ConfigDict, ValidationError
from pydantic_core import PydanticUndefined

from ._errors import ConfigError

__all__ = ["Strict", "validate", "markdown_table", "field_path"]


class Strict(BaseModel):
    """Base of every config schema: unknown keys, coercions and non-finite numbers are errors."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False, frozen=True)


def field_path(loc) -> str:
    """``('datasets', 1, 'split')`` -> ``datasets[1].split``."""
    out = ""
    for x in loc:
        out += f"[{x}]" if isinstance(x, int) else (f".{x}" if out else str(x))
    return out


def _unwrap(ann):
    """The model or Literal a field annotation holds (through Optional, list, dict, Annotated)."""
    origin = typing.get_origin(ann)
    if origin is typing.Annotated:
        return _unwrap(typing.get_args(ann)[0])
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(ann) if a is not type(None)]
        return _unwrap(args[0]) if len(args) == 1 else ann
    if origin in (list, tuple, dict):
        return _unwrap(typing.get_args(ann)[-1])
    return ann


def _field_at(model: type[BaseModel], loc):
    """(model holding the last named key of ``loc``, that key's FieldInfo or None)."""
    cur, info = model, None
    for x in loc:
        if isinstance(x, int):
            continue
        if not (isinstance(cur, type) and issubclass(cur, BaseModel)) or x not in cur.model_fields:
            return cur, None
        info = cur.model_fields[x]
        nxt = _unwrap(info.annotation)
        if isinstance(nxt, type) and issubclass(nxt, BaseModel):
            cur = nxt
        else:
            return cur, info
    return cur, info


_EXPECTED = {
    "greater_than": "a number > {gt}", "greater_than_equal": "a number >= {ge}", "less_than": "a number < {lt}",
    "less_than_equal": "a number <= {le}", "float_type": "a number", "float_parsing": "a number",
    "int_type": "an integer", "int_parsing": "an integer", "int_from_float": "an integer", "bool_type": "true or false",
    "string_type": "a string", "list_type": "a list", "finite_number": "a finite number",
    "too_short": "at least {min_length} item(s)", "string_too_short": "a non-empty string",
}


def _message(model, err) -> tuple[str, str]:
    loc = list(err["loc"])
    ctx = err.get("ctx") or {}
    kind, got = err["type"], err.get("input")
    if ctx.get("at") is not None:
        loc.append(ctx["at"])
    # pydantic names the branch of a tagged value ('function-after[...]'): not a field
    loc = [x for x in loc if isinstance(x, int) or "[" not in str(x)]
    owner, info = _field_at(model, loc)
    if kind == "missing":
        what = f" ({info.description})" if info is not None and info.description else ""
        return field_path(loc), f"missing{what}"
    if kind == "extra_forbidden":
        parent, _ = _field_at(model, loc[:-1])
        allowed = list(parent.model_fields) if isinstance(parent, type) and issubclass(parent, BaseModel) else []
        return field_path(loc), f"unknown key {loc[-1]!r}; allowed keys: {allowed}"
    if kind == "literal_error" and info is not None:
        lit = _unwrap(info.annotation)
        return field_path(loc), f"expected one of {list(typing.get_args(lit))}, got {got!r}"
    if kind in ("model_type", "model_attributes_type", "dict_type"):
        return field_path(loc), f"expected a mapping, got {got!r}"
    if "at" in ctx:  # a custom check: its message already says what it got
        return field_path(loc), err["msg"]
    if kind in _EXPECTED:
        return field_path(loc), f"expected {_EXPECTED[kind].format(**ctx)}, got {got!r}"
    msg = err["msg"]
    if msg.startswith("Value error, "):
        msg = msg[len("Value error, "):]
    elif msg.startswith("Input should be "):
        msg = "expected " + msg[len("Input should be "):]
    if kind not in ("value_error",) and not msg.endswith(repr(got)):
        msg += f", got {got!r}"
    return field_path(loc), msg


_SHOWN = 20  # problems named in a validation message


def validate(model: type[BaseModel], data: Any, file: str | os.PathLike, context: dict | None = None):
    """``model.model_validate(data, context=context)``; a failure raises :class:`ConfigError`
    ``"<file>: field '<path>': <what is expected>, got <value>"`` for the first problem (the
    message counts the others and names their fields)."""
    try:
        return model.model_validate(data, context=context)
    except ValidationError as exc:
        # the first few problems only: a list of 100,000 bad entries would otherwise make a
        # message (and a formatting loop) as long as the list
        raw = exc.errors(include_url=False)
        errs = [_message(model, e) for e in raw[:_SHOWN]]
        fld, msg = errs[0]
        more = sorted({f for f, _ in errs[1:]} - {fld})
        extra = f" and {len(raw) - len(errs)} more" if len(raw) > len(errs) else ""
        tail = f" (also: {', '.join(more)}{extra})" if more else ""
        raise ConfigError(f"{file}: field '{fld or '<top level>'}': {msg}{tail}") from None


def _expects(info) -> str:
    extra = info.json_schema_extra if isinstance(info.json_schema_extra, dict) else {}
    if "expects" in extra:
        return str(extra["expects"])
    ann = info.annotation
    is_list = typing.get_origin(_strip_optional(ann)) is list
    base = _unwrap(ann)
    if typing.get_origin(base) is Literal:
        text = "one of " + ", ".join(f"`{v}`" for v in typing.get_args(base))
    elif isinstance(base, type) and issubclass(base, BaseModel):
        text = "mapping"
    else:
        text = {bool: "true / false", int: "integer", float: "number", str: "string"}.get(base, str(base))
        if typing.get_origin(_strip_optional(ann)) is dict:
            text = f"mapping of {text}s"
        for m in info.metadata:
            for attr, op in (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<=")):
                if isinstance(m, getattr(at, attr.capitalize())):
                    text += f" {op} {getattr(m, attr)}"
            if isinstance(m, at.MinLen) and m.min_length:
                text = f"non-empty {text}" if text == "string" else f"{text}, at least {m.min_length}"
    return f"list of {text}s" if is_list and not text.startswith("one of") else text


def _strip_optional(ann):
    if typing.get_origin(ann) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(ann) if a is not type(None)]
        if len(args) == 1:
            return args[0]
    return ann


def markdown_table(model: type[BaseModel], prefix: str = "") -> str:
    """The schema as a markdown table: field (nested fields as ``datasets[].columns.time``),
    what it expects, its default (blank: required) and its description."""
    rows = ["| field | expects | default | meaning |", "|---|---|---|---|"] if not prefix else []
    for name, info in model.model_fields.items():
        path = f"{prefix}{name}"
        if info.is_required():
            default = "required"
        elif info.default is PydanticUndefined or info.default is None:
            default = ""
        elif isinstance(info.default, BaseModel):
            default = ""
        else:
            d = info.default
            default = f"`{str(d).lower() if isinstance(d, bool) else d}`"
        desc = (info.description or "").replace("|", "\\|")
        rows.append(f"| `{path}` | {_expects(info)} | {default} | {desc} |")
        sub = _unwrap(info.annotation)
        if isinstance(sub, type) and issubclass(sub, BaseModel):
            is_list = typing.get_origin(_strip_optional(info.annotation)) is list
            rows.append(markdown_table(sub, path + ("[]." if is_list else ".")))
    return "\n".join(rows)
