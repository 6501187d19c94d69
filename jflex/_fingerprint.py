"""Content hashes that identify a computation across processes: arrays by their bytes, pytrees by
their leaves and structure (at any depth), functions by qualified name, bytecode and the values they reach
(closure cells, defaults, ``functools.partial`` arguments, module globals that hold arrays or
pytrees), and the fields of dataclasses and ``SimpleNamespace`` objects. What a function
reaches through other routes (attributes of other objects, files) is not seen;
``sweep(key=...)`` covers that."""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import re
import types

import jax
import numpy as np

_ADDR = re.compile(r" at 0x[0-9a-fA-F]+")
# functions reached from functions (through closures and globals) are followed this many hops:
# beyond, a helper's helper's code is named, not read. Data (containers, pytrees, arrays) is
# followed to any depth, so a robot held in dicts of lists of tuples is always seen.
_MAX_FUNCTION_HOPS = 4


def _array_bytes(h, a) -> None:
    a = np.asarray(a)
    h.update(f"array{a.dtype.str}{a.shape}".encode())
    h.update(np.ascontiguousarray(a).tobytes())


def _code(h, code: types.CodeType) -> None:
    h.update(code.co_code)
    h.update(repr(code.co_names).encode())
    for c in code.co_consts:
        if isinstance(c, types.CodeType):
            _code(h, c)
        else:
            h.update(_ADDR.sub("", repr(c)).encode())


def _update(h, obj, depth: int, seen: set) -> None:
    """``depth`` counts function hops only (see ``_MAX_FUNCTION_HOPS``); ``seen`` holds the ids of
    the containers and functions on the path here, so a cycle is named, not followed."""
    if id(obj) in seen:
        h.update(b"<cycle>")
        return
    if isinstance(obj, (types.ModuleType, type)):
        h.update(f"<{getattr(obj, '__name__', '?')}>".encode())
        return
    if obj is None or isinstance(obj, (bool, int, float, complex, str, bytes)):
        h.update(repr(obj).encode())
        return
    if isinstance(obj, (np.ndarray, np.generic, jax.Array)):
        _array_bytes(h, obj)
        return
    seen = seen | {id(obj)}
    if isinstance(obj, functools.partial):
        h.update(b"partial")
        for part in (obj.func, obj.args, obj.keywords):
            _update(h, part, depth + 1, seen)
        return
    if isinstance(obj, types.MethodType):
        _update(h, obj.__func__, depth + 1, seen)
        _update(h, obj.__self__, depth + 1, seen)
        return
    if isinstance(obj, types.FunctionType):
        h.update(f"fn {obj.__module__}.{obj.__qualname__}".encode())
        if depth > _MAX_FUNCTION_HOPS:
            return
        _code(h, obj.__code__)
        for part in (obj.__defaults__, obj.__kwdefaults__):
            _update(h, part, depth + 1, seen)
        for cell in obj.__closure__ or ():
            try:
                _update(h, cell.cell_contents, depth + 1, seen)
            except ValueError:  # an empty cell
                h.update(b"<empty>")
        g = obj.__globals__
        for name in _global_names(obj.__code__):
            if name in g and not isinstance(g[name], (types.ModuleType, type)):
                h.update(name.encode())
                _update(h, g[name], depth + 1, seen)
        return
    if isinstance(obj, types.BuiltinFunctionType):
        h.update(f"builtin {getattr(obj, '__module__', '')}.{obj.__qualname__}".encode())
        return
    if isinstance(obj, dict):
        for k in sorted(obj, key=repr):
            h.update(repr(k).encode())
            _update(h, obj[k], depth, seen)
        return
    leaves, treedef = jax.tree_util.tree_flatten(obj)
    if len(leaves) == 1 and leaves[0] is obj:  # not a pytree: its type and printed form
        h.update(f"{type(obj).__module__}.{type(obj).__qualname__}".encode())
        h.update(_ADDR.sub("", repr(obj)).encode())
        if dataclasses.is_dataclass(obj) or hasattr(obj, "__dict__"):
            # data holders (dataclasses, namespaces, any object's attributes, e.g. a global config
            # object a function reads cfg.gain from): their fields, which a repr leaves out
            _update(h, dict(vars(obj)) if hasattr(obj, "__dict__") else
                    {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)}, depth, seen)
        return
    h.update(_ADDR.sub("", str(treedef)).encode())
    for leaf in leaves:
        _update(h, leaf, depth, seen)


def _global_names(code: types.CodeType):
    names = list(code.co_names)
    for c in code.co_consts:
        if isinstance(c, types.CodeType):
            names += _global_names(c)
    return dict.fromkeys(names)


def fingerprint(*objs) -> str:
    """Hex SHA-256 of ``objs`` (arrays, pytrees such as a Robot or Model, functions, scalars)."""
    h = hashlib.sha256()
    for o in objs:
        _update(h, o, 0, set())
        h.update(b"|")
    return h.hexdigest()
