"""How much of a run went to tracing and compiling, from JAX's own monitoring events.

The command line prints it after every command and writes it beside a run's results
(``compile_time.json``), so a user can tell a run that waited on XLA from one that computed, and
see what the persistent compilation cache saved. JAX stores no program that calls back into
Python (an ``eqx.error_if`` check inside ``jit``); those compile again in every process.
"""

from __future__ import annotations

import collections
import time

_EVENTS = {
    "/jax/core/compile/jaxpr_trace_duration": "trace_s",
    "/jax/core/compile/jaxpr_to_mlir_module_duration": "lower_s",
    "/jax/core/compile/backend_compile_duration": "compile_s",
    "/jax/compilation_cache/cache_retrieval_time_sec": "cache_read_s",
    "/jax/compilation_cache/compile_time_saved_sec": "cache_saved_s",
}
_COUNTS = {"/jax/compilation_cache/cache_hits": "cache_hits", "/jax/compilation_cache/cache_misses": "cache_misses"}
_TOTALS: collections.Counter = collections.Counter()
_LISTENING = False


def _on_duration(event, duration, **_):
    key = _EVENTS.get(event)
    if key is not None:
        _TOTALS[key] += duration
        if key == "compile_s":
            _TOTALS["programs"] += 1


def _on_event(event, **_):
    key = _COUNTS.get(event)
    if key is not None:
        _TOTALS[key] += 1


class CompileClock:
    """Wall time and JAX's tracing/compiling time since it was made (listeners registered once
    per process)."""

    def __init__(self):
        global _LISTENING
        if not _LISTENING:
            from jax import monitoring

            monitoring.register_event_duration_secs_listener(_on_duration)
            monitoring.register_event_listener(_on_event)
            _LISTENING = True
        self._t0, self._start = time.perf_counter(), dict(_TOTALS)

    def summary(self) -> dict:
        out = {k: _TOTALS[k] - self._start.get(k, 0) for k in (*_EVENTS.values(), *_COUNTS.values(), "programs")}
        out["wall_s"] = time.perf_counter() - self._t0
        out["tracing_and_compiling_s"] = out["trace_s"] + out["lower_s"] + out["compile_s"]
        return out

    def line(self) -> str:
        s = self.summary()
        cache = (f"; {int(s['cache_hits'])} read from the compilation cache (saving {s['cache_saved_s']:.1f} s)"
                 if s["cache_hits"] or s["cache_misses"] else "")
        return (f"{s['wall_s']:.1f} s in all, of which {s['tracing_and_compiling_s']:.1f} s tracing and compiling "
                f"{int(s['programs'])} programs{cache}")
