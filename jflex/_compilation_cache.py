"""A persistent compilation cache: compiled XLA programs are kept on disk and reused by later
processes, so the second run of the same analysis on the same robot starts warm.

It is JAX's own cache (``jax_compilation_cache_dir``); jflex only picks the folder and the
thresholds. Entries are keyed by the program, the JAX/XLA versions, the compiler flags and the
device, so a cache is never used for a program it does not fit; a folder can be shared between
runs, moved (point ``JFLEX_CACHE_DIR`` or ``path`` at the new place) or deleted at any time (the
next run compiles again and refills it).
"""

from __future__ import annotations

import os
import pathlib

from ._errors import ConfigError
from ._paths import output_folder

ENV_VAR = "JFLEX_CACHE_DIR"


def default_cache_dir() -> pathlib.Path:
    """``$JFLEX_CACHE_DIR`` if set, else ``$XDG_CACHE_HOME/jflex/jax`` (``~/.cache/jflex/jax``)."""
    if os.environ.get(ENV_VAR):
        return pathlib.Path(os.environ[ENV_VAR]).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or pathlib.Path.home() / ".cache"
    return pathlib.Path(base).expanduser() / "jflex" / "jax"


def enable_compilation_cache(path: str | os.PathLike | None = None, *, min_compile_time_s: float = 0.1,
                             min_entry_size_bytes: int = 0) -> pathlib.Path:
    """Keep compiled programs in ``path`` and reuse them across processes (JAX's persistent
    compilation cache), for this whole process from now on.

    **Arguments:**

    - ``path``: the cache folder (created if missing). Default: ``$JFLEX_CACHE_DIR``, else
      ``~/.cache/jflex/jax`` (``$XDG_CACHE_HOME/jflex/jax`` where that is set).
    - ``min_compile_time_s``: programs that compiled faster than this are not stored (JAX's
      default of 1 s would skip many of jflex's per-robot kernels, which compile in 0.1-1 s on CPU).
    - ``min_entry_size_bytes``: programs smaller than this are not stored.

    **Returns:** the folder in use.

    The traced programs of ``jflex.sweep`` and of the diagnosis are kept there too
    (``jflex-programs/``), so a later process skips tracing them as well (see
    ``jflex/_program_cache.py`` for what their key covers).

    To clear the cache, delete the folder; to move it, move the folder and pass the new ``path``
    (or set ``JFLEX_CACHE_DIR``). Programs compiled before this call are not stored.
    """
    folder = output_folder(path if path is not None else default_cache_dir(), "enable_compilation_cache: path")
    if not os.access(folder, os.W_OK):
        raise ConfigError(f"enable_compilation_cache: path {str(folder)!r} is not writable")
    if not min_compile_time_s >= 0:
        raise ConfigError(f"enable_compilation_cache: min_compile_time_s must be >= 0, got {min_compile_time_s}")
    if not int(min_entry_size_bytes) >= 0:
        raise ConfigError(f"enable_compilation_cache: min_entry_size_bytes must be >= 0, got {min_entry_size_bytes}")
    import jax

    jax.config.update("jax_compilation_cache_dir", str(folder))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", float(min_compile_time_s))
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", int(min_entry_size_bytes))
    from ._program_cache import set_folder

    set_folder(folder)  # traced programs beside the compiled ones (jflex/_program_cache.py)
    try:
        # JAX decides once, at its first compile, whether a cache is in use: forget that decision so
        # a call after some compilation still takes effect
        from jax.experimental.compilation_cache import compilation_cache

        compilation_cache.reset_cache()
    except (ImportError, AttributeError):  # another JAX layout: the config alone applies
        pass
    return folder
