"""One convention for every subcommand and experiment: a YAML config in, one run folder out.

Every run takes a config (a YAML file, with a sensible default), accepts ``--out DIR`` and
writes ``DIR/results.json`` (the figures it computed, each with its unit) plus its plots. Without
``--out`` it makes a fresh folder ``runs/<name>-<timestamp>``.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import math
import os
import pathlib
import re
import sys
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
import yaml

from ._errors import ConfigError


def make_run_dir(name: str, out: str | os.PathLike | None = None) -> pathlib.Path:
    """Return the run folder: ``out`` if given (created), else a fresh ``runs/<name>-<stamp>``."""
    if out is not None:
        path = pathlib.Path(out)
    else:
        stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
        path = pathlib.Path("runs") / f"{name}-{stamp}"
        k = 1
        while path.exists():
            path = pathlib.Path("runs") / f"{name}-{stamp}-{k}"
            k += 1
    path.mkdir(parents=True, exist_ok=True)
    return path


def _jsonable(x: Any) -> Any:
    if isinstance(x, Mapping):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if hasattr(x, "__array__") and not isinstance(x, (str, bytes)):
        arr = np.asarray(x)
        if np.iscomplexobj(arr):
            return {"real": _jsonable(arr.real), "imag": _jsonable(arr.imag)}
        return _jsonable(arr.tolist()) if arr.ndim else _jsonable(arr.item())
    if isinstance(x, float) and not math.isfinite(x):
        return str(x)  # JSON has no NaN/inf; keep them visible rather than dropping them
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (np.floating,)):
        return _jsonable(float(x))
    return x


def write_results(run_dir: str | os.PathLike, results: Mapping[str, Any], name: str = "results.json") -> pathlib.Path:
    """Write ``results`` (nested dicts of numbers/arrays, units in the keys or a ``unit`` field) as JSON.

    Written to a temporary file first and renamed, so an interrupted run never leaves a torn file.
    """
    path = pathlib.Path(run_dir) / name
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(_jsonable(results), indent=2))
    os.replace(tmp, path)
    return path


# A config is a few hundred nodes; a case with inline tables a few thousand (data live in data
# files). Aliases let 1 KB of YAML stand for 1e9 nodes ("billion laughs"): PyYAML builds them as
# shared objects, so the load is quick, and whatever walks the result next (validation, a copy,
# JSON) hangs or runs out of memory. The limit is on the document as if every alias were written
# out, and low enough that validating that many wrong entries still takes seconds, not minutes.
MAX_YAML_NODES = 100_000


class _Refused(yaml.YAMLError):
    """A YAML document jflex does not read (duplicate key, alias bomb, recursive alias)."""


class _Loader(yaml.SafeLoader):
    """Safe loading that reads ``2.1e11`` as a number, as YAML 1.2 does: YAML 1.1 wants
    ``2.1e+11`` and PyYAML hands the rest over as strings, which a schema rightly refuses.

    It also refuses what PyYAML accepts silently: a key given twice in one mapping (the last one
    would win; a typo'd copy of a block would override the real one), a recursive alias, and a
    document whose aliases expand past :data:`MAX_YAML_NODES` nodes."""

    def compose_document(self):
        node = super().compose_document()
        if node is not None:
            _expanded_size(node, {}, set())
        return node

    def construct_mapping(self, node, deep=False):
        if isinstance(node, yaml.MappingNode):
            first: dict = {}
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue  # `<<: *base` then a key of the same name overrides it, as YAML means
                key = self.construct_object(key_node, deep=True)
                line = key_node.start_mark.line + 1
                try:
                    prev = first.get(key)
                except TypeError:
                    continue  # unhashable: SafeConstructor says so itself
                if prev is not None:
                    raise _Refused(f"duplicate key {key!r} at line {line} (first given at line {prev}); "
                                   "each key may appear once in a mapping")
                first[key] = line
        return super().construct_mapping(node, deep=deep)


def _expanded_size(node, sizes: dict, active: set) -> int:
    """Nodes of ``node`` with every alias written out (memoised on shared nodes, so a bomb is
    measured without being expanded); refuses a recursive alias and a total past the limit."""
    key = id(node)
    if key in sizes:
        return sizes[key]
    if key in active:
        raise _Refused(f"recursive alias at line {node.start_mark.line + 1}: a config cannot contain itself")
    active.add(key)
    total = 1
    if isinstance(node, yaml.SequenceNode):
        children = node.value
    elif isinstance(node, yaml.MappingNode):
        children = [n for pair in node.value for n in pair]
    else:
        children = ()
    for child in children:
        total += _expanded_size(child, sizes, active)
        if total > MAX_YAML_NODES:
            raise _Refused(
                f"the document expands to more than {MAX_YAML_NODES:,} nodes through its aliases "
                f"(&anchor / *alias, the one at line {node.start_mark.line + 1}); write the data out or "
                "keep it in a data file"
            )
    active.discard(key)
    sizes[key] = total
    return total


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9][0-9_]*)[eE][-+]?[0-9]+$"),
    list("-+.0123456789"),
)


def load_yaml(path: str | os.PathLike) -> dict:
    """Read a YAML mapping; a missing file or a non-mapping top level is a :class:`ConfigError`."""
    path = pathlib.Path(path)
    try:
        if not path.is_file():
            raise ConfigError(f"{path}: config file not found")
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{path}: not UTF-8 text (undecodable byte at offset {exc.start})") from None
    except (OSError, ValueError) as exc:  # a name too long, a NUL byte, no permission
        shown = str(path) if len(str(path)) <= 120 else str(path)[:100] + f"... ({len(str(path))} characters)"
        why = "contains a NUL byte" if "\x00" in str(path) else (exc.strerror or type(exc).__name__) if isinstance(exc, OSError) else str(exc)
        raise ConfigError(f"{shown!r}: cannot read this config file ({why})") from None
    try:
        data = yaml.load(text, Loader=_Loader)
    except _Refused as exc:
        raise ConfigError(f"{path}: {exc}") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: not valid YAML ({exc})") from None
    except RecursionError:
        raise ConfigError(f"{path}: nested too deeply to read (thousands of levels of [ or {{)") from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a mapping at the top level, got {type(data).__name__}")
    return data


Check = Callable[[Mapping[str, Any]], Mapping[str, tuple[float, float, float]]]


def quick_check(name: str, figures: Mapping[str, tuple[float, float, float]]) -> dict:
    """Print each ``figure: (value, low, high)`` and raise a :class:`JFlexError` naming those
    outside ``[low, high]`` (or not finite). Returns them as ``{figure: {value, low, high, ok}}``."""
    from ._errors import JFlexError

    rows, bad = {}, []
    for fig, (value, low, high) in figures.items():
        value = float(value)
        ok = math.isfinite(value) and low <= value <= high
        rows[fig] = {"value": value, "low": low, "high": high, "ok": ok}
        print(f"{name} --quick: {fig} = {value:.6g} ({'ok' if ok else 'OUT OF'} [{low:.6g}, {high:.6g}])", flush=True)
        if not ok:
            bad.append(f"{fig} = {value:.6g} not in [{low:.6g}, {high:.6g}]")
    if bad:
        raise JFlexError(f"{name} --quick: " + "; ".join(bad))
    return rows


def experiment_cli(
    name: str,
    default_config: str | os.PathLike,
    run: Callable[[dict, pathlib.Path], Mapping[str, Any]],
    argv: Sequence[str] | None = None,
    description: str | None = None,
    schema: type | None = None,
    quick: tuple[str | os.PathLike, Check] | None = None,
) -> pathlib.Path:
    """Parse ``[CONFIG] [--out DIR] [--quick]``, call ``run(config_dict, run_dir)`` and write its results.

    ``run`` returns the results mapping; it may also write plots into ``run_dir``.
    ``schema``: a pydantic model of the config (``extra="forbid"`` refuses unknown keys); the YAML
    is validated against it before ``run`` (a :class:`ConfigError` naming file and field) and
    ``run`` gets its dump, defaults filled in. ``quick``: ``(config, check)``: ``--quick`` runs
    that (small) config unless one is named, then ``check(results)`` gives the key figures as
    ``{figure: (value, low, high)}``, loose bounds around their references, which
    :func:`quick_check` prints and enforces (a run that passes them under ``results["quick_check"]``).
    Returns the run folder.
    """
    parser = argparse.ArgumentParser(prog=name, description=description)
    parser.add_argument("config", nargs="?", default=None, help=f"YAML config (default: {default_config})")
    parser.add_argument("--out", default=None, help="run folder (default: a fresh runs/<name>-<time>)")
    if quick is not None:
        parser.add_argument("--quick", action="store_true",
                            help=f"a small run (under a minute; default config {pathlib.Path(quick[0]).name}) whose key "
                            "figures are checked loosely against their references")
    args = parser.parse_args(argv)
    is_quick = getattr(args, "quick", False)
    if args.config is None:
        args.config = str(quick[0] if is_quick else default_config)
    cfg = load_yaml(args.config)
    if schema is not None:
        from ._schema import validate

        cfg = validate(schema, cfg, args.config).model_dump()
    run_dir = make_run_dir(name, args.out)
    # at once, on a terminal or not: a run that computes for minutes before its first line of
    # output otherwise looks hung in a log or a notebook
    print(f"{name}: running {args.config} into {run_dir}", file=sys.stderr, flush=True)
    results = dict(run(cfg, run_dir))
    results.setdefault("config", str(args.config))
    write_results(run_dir, results)
    if is_quick:
        results["quick_check"] = quick_check(name, quick[1](results))
        write_results(run_dir, results)
    print(f"{name}: results in {run_dir / 'results.json'}")
    return run_dir
