"""Progress on stderr for long runs (tqdm): counted bars (sweeps, fit steps, bench cases) and a
stage line (diagnose, demo) whose clock keeps ticking through a long stage.

Shown only where a person watches: ``progress=False`` turns it off, and so does a stderr that is
not a terminal (a log file, a pipe, a CI job), where carriage-return redraws would be garbage.
Progress never touches what a run computes.
"""

from __future__ import annotations

import contextlib
import sys
import threading
import time
from collections.abc import Callable, Iterator


def shown(progress=True) -> bool:
    """Whether progress is drawn: asked for (``progress`` truthy) and stderr is a terminal."""
    if progress is None or progress is False or (not callable(progress) and not progress):
        return False
    isatty = getattr(sys.stderr, "isatty", None)
    return bool(isatty and isatty())


def bar(total: int, label: str, progress=True, unit: str = "it"):
    """A tqdm bar on stderr over ``total`` items named ``label`` (a silent one when not
    :func:`shown`). Use as a context manager; ``update(n)``, ``set_postfix_str(s)``, ``write(s)``."""
    from tqdm import tqdm

    return tqdm(total=total, desc=label, unit=unit, file=sys.stderr, disable=not shown(progress),
                dynamic_ncols=True, leave=True)


def note(message: str, progress=True) -> None:
    """One finished line on stderr (above any bar) when progress is :func:`shown`."""
    if shown(progress):
        from tqdm import tqdm

        tqdm.write(message, file=sys.stderr)


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
    passed through unchanged; ``True`` gives a tqdm stage line on stderr (nothing when stderr is
    not a terminal); ``False``/``None`` a no-op."""
    if callable(progress):
        yield progress
        return
    if not shown(progress):
        yield lambda stage: None
        return
    line = _StageLine(label)
    try:
        yield line
    finally:
        line.close()
