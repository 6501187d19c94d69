"""Traced programs kept on disk, so a later process skips tracing as well as compiling.

JAX's persistent compilation cache (:func:`jflex.enable_compilation_cache`) stores compiled code,
but every process still traces each program to find it: a diagnosis' row-wise programs traced for
about 5 s of a 15 s warm run. :func:`persistent_jit` is ``equinox.filter_jit`` whose traced and
lowered program is also exported (``jax.export``) into ``<cache folder>/jflex-programs`` the first
time, and read back by later processes instead of tracing the function again.

A stored program is used only where its key proves it is the same program: the bytes of every
source file of jflex, the JAX and jaxlib versions, the backend and the precision, the trace-time
modes of jflex, the shapes and dtypes of the array arguments, and every other argument and
closed-over value, hashed by content. Only values whose content can be hashed completely take
part: numbers, strings, arrays, containers, dataclasses and equinox modules, and functions and
classes of jflex, JAX, NumPy or equinox. Anything else (a user's own effect class, an object of
unknown make) sends the call down the plain ``filter_jit`` path, as does a program that cannot be
exported or an entry that cannot be read. The folder can be deleted at any time.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import hashlib
import os
import pathlib
import types

import equinox as eqx
import jax
import numpy as np

from ._checks import _COLLECTED
from ._fingerprint import _ADDR, _array_bytes
from ._trig import _VECTORISED

_FOLDER: pathlib.Path | None = None
_MEMORY = 64  # programs kept in memory per function, and loaded programs by key
_LOADED: dict = {}  # key -> (jitted call of the exported program, output skeleton)
_SUBFOLDER = "jflex-programs"
_FORMAT = b"jflex-program-1\n"
_PACKAGE = pathlib.Path(__file__).resolve().parent
# modules whose functions and classes are named, not read: jflex's own are covered by the hash of
# its sources, the others by their versions in the key
_NAMED = ("jflex", "jax", "jaxlib", "numpy", "equinox", "math", "operator", "builtins")


def set_folder(cache_folder: pathlib.Path | None) -> None:
    """Store traced programs beside the compiled ones in ``cache_folder`` (None: stop storing)."""
    global _FOLDER
    _FOLDER = None if cache_folder is None else pathlib.Path(cache_folder) / _SUBFOLDER


class _Unkeyable(Exception):
    """A value whose content cannot be hashed completely."""


@functools.cache
def _environment() -> bytes:
    h = hashlib.sha256(_FORMAT)
    for path in sorted(_PACKAGE.rglob("*.py")):
        h.update(str(path.relative_to(_PACKAGE)).encode())
        h.update(path.read_bytes())
    import jaxlib

    h.update(f"{jax.__version__}|{jaxlib.__version__}|{np.__version__}|{eqx.__version__}".encode())
    return h.digest()


def _modes() -> tuple:
    """Everything outside the arguments that changes what jflex traces."""
    return (jax.default_backend(), bool(jax.config.jax_enable_x64), str(jax.config.jax_default_matmul_precision),
            _VECTORISED.get(), _COLLECTED.get() is not None)


def _named(obj) -> bool:
    module = getattr(obj, "__module__", None) or ""
    return module.split(".")[0] in _NAMED


def _update(h, obj, seen: frozenset) -> None:
    if id(obj) in seen:
        raise _Unkeyable("a cycle")
    if obj is None or isinstance(obj, (bool, int, float, complex, str, bytes)):
        h.update(f"{type(obj).__name__}:{obj!r};".encode())
        return
    if isinstance(obj, (np.ndarray, np.generic)) or (isinstance(obj, jax.Array) and not isinstance(obj, jax.core.Tracer)):
        _array_bytes(h, obj)
        return
    if isinstance(obj, jax.core.Tracer):
        raise _Unkeyable("a traced value")
    if isinstance(obj, np.dtype):
        h.update(f"dtype:{obj.str};".encode())
        return
    seen = seen | {id(obj)}
    if isinstance(obj, enum.Enum):
        _update(h, type(obj), seen)
        h.update(f"member:{obj.name};".encode())
        return
    if isinstance(obj, (tuple, list)):
        h.update(f"{type(obj).__name__}[{len(obj)}](".encode())
        for x in obj:
            _update(h, x, seen)
        h.update(b")")
        return
    if isinstance(obj, dict):
        h.update(f"dict[{len(obj)}](".encode())
        for k, v in obj.items():
            _update(h, k, seen)
            _update(h, v, seen)
        h.update(b")")
        return
    if isinstance(obj, types.ModuleType):
        if obj.__name__.split(".")[0] not in _NAMED:
            raise _Unkeyable(f"module {obj.__name__}")
        h.update(f"module:{obj.__name__};".encode())
        return
    if isinstance(obj, type):
        if not _named(obj):
            raise _Unkeyable(f"class {obj.__module__}.{obj.__qualname__}")
        h.update(f"class:{obj.__module__}.{obj.__qualname__};".encode())
        return
    if isinstance(obj, functools.partial):
        h.update(b"partial(")
        for part in (obj.func, obj.args, obj.keywords):
            _update(h, part, seen)
        h.update(b")")
        return
    if isinstance(obj, types.MethodType):
        h.update(b"method(")
        _update(h, obj.__func__, seen)
        _update(h, obj.__self__, seen)
        h.update(b")")
        return
    if isinstance(obj, types.FunctionType):
        if not _named(obj):
            raise _Unkeyable(f"function {obj.__module__}.{obj.__qualname__}")
        code = obj.__code__
        # the module's source is in the key; the line tells two lambdas of one scope apart
        h.update(f"function:{obj.__module__}.{obj.__qualname__}:{code.co_firstlineno};".encode())
        cells = tuple(c.cell_contents for c in obj.__closure__ or ())
        _update(h, (cells, obj.__defaults__, obj.__kwdefaults__), seen)
        return
    if isinstance(obj, (types.BuiltinFunctionType, np.ufunc)) or type(obj).__name__ == "PjitFunction":
        if not _named(obj) and not isinstance(obj, np.ufunc):
            raise _Unkeyable(f"callable {obj!r}")
        h.update(f"callable:{getattr(obj, '__module__', '')}.{getattr(obj, '__qualname__', getattr(obj, '__name__', ''))};".encode())
        wrapped = getattr(obj, "__wrapped__", None)
        if wrapped is not None:
            _update(h, wrapped, seen)
        return
    content = getattr(type(obj), "_content_key", None)
    if content is not None:  # (module, ...): an object that says what it is made of
        module, *rest = content(obj)
        if (module or "").split(".")[0] not in _NAMED:
            raise _Unkeyable(f"code of module {module}")
        _update(h, (type(obj), module, *rest), seen)
        return
    if dataclasses.is_dataclass(obj):  # equinox modules are dataclasses
        _update(h, type(obj), seen)
        h.update(b"fields(")
        for f in dataclasses.fields(obj):
            h.update(f"{f.name}=".encode())
            _update(h, getattr(obj, f.name, None), seen)
        h.update(b")")
        return
    raise _Unkeyable(f"a {type(obj).__module__}.{type(obj).__qualname__}")


def _key(fn, static, treedef, avals) -> str | None:
    """The hex key of a program, or None when some value cannot be hashed completely."""
    h = hashlib.sha256(_environment())
    # the structure of the array arguments (where each one sits); what else the tree's text shows
    # (functions, with their addresses) is hashed by content with the other arguments below
    h.update(repr((_modes(), _ADDR.sub("", str(treedef)), avals)).encode())
    try:
        _update(h, fn, frozenset())
        _update(h, static, frozenset())  # the non-array arguments, modules' static fields included
    except _Unkeyable:
        return None
    return h.hexdigest()


def _aval(x):
    return (tuple(np.shape(x)), np.dtype(x.dtype).str, bool(getattr(x, "weak_type", False)))


def _write(path: pathlib.Path, blob: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_bytes(blob)
    os.replace(tmp, path)


_ARRAY = "\x00jflex-array"  # marks where an array output sits in a stored output skeleton


def _skeleton(out, leaves: list):
    """``out`` with each array replaced by ``(_ARRAY, k)`` (its index in ``leaves``): Python
    literals only, so a stored entry is read with ``ast.literal_eval`` and never runs code."""
    if eqx.is_array(out):
        leaves.append(out)
        return (_ARRAY, len(leaves) - 1)
    if out is None or isinstance(out, (bool, int, float, str)):
        return out
    if type(out) in (tuple, list):
        return type(out)(_skeleton(x, leaves) for x in out)
    if type(out) is dict and all(isinstance(k, (str, int)) for k in out):
        return {k: _skeleton(v, leaves) for k, v in out.items()}
    raise _Unkeyable(f"an output of type {type(out).__name__}")


def _filled(skeleton, leaves):
    if type(skeleton) is tuple and len(skeleton) == 2 and skeleton[0] == _ARRAY:
        return leaves[skeleton[1]]
    if type(skeleton) in (tuple, list):
        return type(skeleton)(_filled(x, leaves) for x in skeleton)
    if type(skeleton) is dict:
        return {k: _filled(v, leaves) for k, v in skeleton.items()}
    return skeleton


def _read(path: pathlib.Path):
    """``(exported, skeleton)`` from a stored entry, or None when it cannot be read."""
    import ast

    from jax import export

    try:
        blob = path.read_bytes()
        head = len(_FORMAT)
        body = blob[head + 32:]
        if not blob.startswith(_FORMAT) or hashlib.sha256(body).digest() != blob[head:head + 32]:
            return None
        n = int.from_bytes(body[:8], "little")
        skeleton = ast.literal_eval(body[8:8 + n].decode())
        return export.deserialize(bytearray(body[8 + n:])), skeleton
    except Exception:  # a damaged or foreign entry is exported again, never trusted
        return None


class _Persistent:
    """``equinox.filter_jit(fn)`` with its traced program kept on disk (see the module's notes)."""

    def __init__(self, fn):
        self._fn = fn
        self._jit = eqx.filter_jit(fn)
        self._programs: dict = {}
        functools.update_wrapper(self, fn)

    def __call__(self, *args):
        folder = _FOLDER
        if folder is None:
            return self._jit(*args)
        dynamic, static = eqx.partition(args, eqx.is_array)
        leaves, treedef = jax.tree_util.tree_flatten(dynamic)
        if any(isinstance(x, jax.core.Tracer) or (isinstance(x, jax.Array) and len(x.sharding.device_set) > 1)
               for x in leaves):  # traced, or spread over devices: a program exported for one would not fit
            return self._jit(*args)
        avals = tuple(_aval(x) for x in leaves)
        static_leaves, static_def = jax.tree_util.tree_flatten(static)
        try:
            known = (treedef, static_def, tuple(static_leaves), avals, _modes())
            program = self._programs.get(known)
        except TypeError:  # an unhashable static value: filter_jit raises as it always has
            return self._jit(*args)
        if program is None:
            if len(self._programs) >= _MEMORY:  # new closures each call would grow it without end
                self._programs.pop(next(iter(self._programs)))
            program = self._programs[known] = self._program(folder, static, treedef, avals) or False
        if program is False:
            return self._jit(*args)
        call, skeleton = program
        try:
            out = call(*leaves)
        except (TypeError, ValueError):  # refused at dispatch (an argument the export did not expect)
            self._programs[known] = False
            return self._jit(*args)
        return _filled(skeleton, out)

    def _program(self, folder, static, treedef, avals):
        key = _key(self._fn, static, treedef, avals)
        if key is None:
            return None
        if key in _LOADED:
            return _LOADED[key]
        path = folder / f"{key}.jfx"
        stored = _read(path) if path.exists() else None
        if stored is None:
            stored = self._export(static, treedef, avals, path)
            if stored is None:
                return None
        exported, skeleton = stored
        if len(_LOADED) >= _MEMORY:
            _LOADED.pop(next(iter(_LOADED)))
        _LOADED[key] = (jax.jit(exported.call), skeleton)
        return _LOADED[key]

    def _export(self, static, treedef, avals, path):
        from jax import export

        box = []

        def flat(*leaves):
            out_leaves = []
            box.append(_skeleton(self._fn(*eqx.combine(jax.tree_util.tree_unflatten(treedef, leaves), static)), out_leaves))
            return out_leaves

        shapes = [jax.ShapeDtypeStruct(s, np.dtype(d), weak_type=w) for s, d, w in avals]
        try:
            exported = export.export(jax.jit(flat))(*shapes)
            skeleton = repr(box[-1]).encode()
            blob = exported.serialize()
        except Exception:  # not exportable (a host callback, a custom call outside JAX's stable set,
            return None  # an output that is not arrays in tuples, lists and dicts)
        try:
            body = len(skeleton).to_bytes(8, "little") + skeleton + bytes(blob)
            _write(path, _FORMAT + hashlib.sha256(body).digest() + body)  # a damaged entry fails the checksum
        except OSError:  # a read-only cache: this process still uses the exported program
            pass
        return exported, box[-1]


def persistent_jit(fn):
    """``equinox.filter_jit(fn)`` whose traced program a later process reads from the cache folder
    instead of tracing ``fn`` again, while :func:`jflex.enable_compilation_cache` is on."""
    return _Persistent(fn)
