"""Progress on stderr for long runs: counted bars (sweeps, fit steps, bench cases) and a stage
line (diagnose, demo) whose clock keeps ticking through a long stage.

On a terminal they are tqdm's redrawn lines. Where stderr is not a terminal (a notebook, a log
file, ``| tee``, a CI job) carriage-return redraws would be garbage, but silence for minutes is
worse: there each stage is one plain line when it starts, and a counted loop writes a line when
it starts, at most one every :data:`PLAIN_EVERY_S` seconds while it runs, and one when it ends.
``progress=False`` turns both off. Progress never touches what a run computes.
"""

from __future__ import annotations

import contextlib
import sys
import threading
import time
from collections.abc import Callable, Iterator


# a long loop in a log writes a line at most this often (and at its start and end)
PLAIN_EVERY_S = 5.0


def _asked(progress) -> bool:
    return not (progress is None or progress is False or (not callable(progress) and not progress))


def _tty() -> bool:
    isatty = getattr(sys.stderr, "isatty", None)
    try:
        return bool(isatty and isatty())
    except ValueError:  # a closed stream
        return False


def shown(progress=True) -> bool:
    """Whether progress is drawn as redrawn lines: asked for (``progress`` truthy) and stderr is a
    terminal."""
    return _asked(progress) and _tty()


def plain(progress=True) -> bool:
    """Whether progress is written as plain lines: asked for, and stderr is not a terminal."""
    return _asked(progress) and not _tty()


def _say(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


class _PlainBar:
    """The part of tqdm's bar the library uses, as plain lines: ``label: 0/N`` at the start, the
    count (with the postfix) at most every :data:`PLAIN_EVERY_S` s, and the total time at the end."""

    def __init__(self, total, label, unit):
        self.total, self.label, self.unit, self.n, self.postfix = total, label, unit, 0, ""
        self.t0 = self.t_last = time.perf_counter()
        _say(f"{label}: 0/{total} {unit}")

    def update(self, n=1):
        self.n += n
        now = time.perf_counter()
        if now - self.t_last >= PLAIN_EVERY_S and (self.total is None or self.n < self.total):
            self.t_last = now
            _say(f"{self.label}: {self.n}/{self.total} {self.unit} ({now - self.t0:.0f} s){self._post()}")

    def _post(self):
        return f", {self.postfix}" if self.postfix else ""

    def set_postfix_str(self, s="", refresh=True):
        self.postfix = str(s)

    def set_description_str(self, desc=None, refresh=True):
        self.label = str(desc or "")

    def write(self, s, file=None):
        _say(str(s))

    def close(self):
        if self.label is not None:
            _say(f"{self.label}: {self.n}/{self.total} {self.unit} done in {time.perf_counter() - self.t0:.1f} s{self._post()}")
            self.label = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


def bar(total: int, label: str, progress=True, unit: str = "it"):
    """A bar on stderr over ``total`` items named ``label``: tqdm's on a terminal, plain lines
    otherwise, nothing when ``progress`` is off. Use as a context manager; ``update(n)``,
    ``set_postfix_str(s)``, ``set_description_str(s)`` (a new label), ``write(s)``."""
    if plain(progress):
        return _PlainBar(total, label, unit)
    from tqdm import tqdm

    return tqdm(total=total, desc=label, unit=unit, file=sys.stderr, disable=not shown(progress),
                dynamic_ncols=True, leave=True)


def note(message: str, progress=True) -> None:
    """One finished line on stderr (above any bar) when progress is asked for."""
    if shown(progress):
        from tqdm import tqdm

        tqdm.write(message, file=sys.stderr)
    elif plain(progress):
        _say(message)


class _StageLine:
    """The current stage on one redrawn line with its elapsed time; each finished stage is
    left above it with its duration (an indented message is a detail, left above as it is). A daemon thread redraws once a second, so a stage that
    runs for minutes (a compile, a refit) still shows the clock moving."""

    def __init__(self, label: str):
        from tqdm import tqdm

        self.label = label
        self.stage, self.t_stage = "starting", time.perf_counter()
        self.bar = tqdm(total=None, desc=f"{label}: starting", file=sys.stderr, dynamic_ncols=True,
                        bar_format="{desc} [{elapsed}]", leave=False)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._tick, daemon=True)
        self._thread.start()

    def _tick(self):
        while not self._stop.wait(1.0):
            self.bar.refresh()

    def __call__(self, stage: str) -> None:
        if stage[:1].isspace():  # an indented line is a detail of the current stage (one candidate's result)
            self.bar.write(f"{self.label}: {stage.rstrip()}", file=sys.stderr)
            return
        self._finish_stage()
        self.stage, self.t_stage = str(stage), time.perf_counter()
        # the line shows the stage's first line only; a long message is kept whole above it
        self.bar.set_description_str(f"{self.label}: {self.stage.strip().splitlines()[0][:100]}")

    def _finish_stage(self):
        if self.stage != "starting":
            self.bar.write(f"{self.label}: {self.stage} ({time.perf_counter() - self.t_stage:.1f} s)", file=sys.stderr)

    def close(self):
        self._stop.set()
        self._thread.join()
        self._finish_stage()
        self.bar.close()


@contextlib.contextmanager
def stages(label: str, progress=True) -> Iterator[Callable[[str], None]]:
    """A ``say(stage)`` callable for the ``with`` block: a user's own callable ``progress`` is
    passed through unchanged; ``True`` gives a tqdm stage line on a terminal and one plain line
    per stage elsewhere; ``False``/``None`` a no-op."""
    if callable(progress):
        yield progress
        return
    if plain(progress):
        t0 = time.perf_counter()
        yield lambda stage: _say(f"{label}: {str(stage).rstrip()}")
        _say(f"{label}: done ({time.perf_counter() - t0:.1f} s)")
        return
    if not shown(progress):
        yield lambda stage: None
        return
    line = _StageLine(label)
    try:
        yield line
    finally:
        line.close()
