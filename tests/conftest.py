import os
import pathlib
import sys

import jax

# the gap bench's generators live outside the library (benchmarks/gap): tests import them by path
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "gap"))

jax.config.update("jax_enable_x64", True)

# the command line keeps compiled programs in a user-wide cache by default; the command lines the
# tests start compile afresh, so a result never depends on what an earlier run left there
# (tests/test_cli_cache.py turns it back on in its own folders)
os.environ.setdefault("JFLEX_NO_CACHE", "1")

# Heavier cases run at a small size unless JFLEX_SLOW=1.
SLOW = os.environ.get("JFLEX_SLOW", "0") == "1"


# Files that take half a minute or more on two cores, longest first (each file's test durations
# summed, on a quiet machine). `--dist loadfile` hands whole files to the two workers in queue
# order, and xdist queues the files with the most tests first: a long file with few tests came
# last, one worker running it while the other idled. These go first (longest processing time
# first); the other files keep xdist's order.
LONG_FILES = ("test_gap_realistic.py", "test_flexible_link.py", "test_gap.py", "test_frf_jacobian.py",
              "test_gap_response.py", "test_identify_fit.py", "test_simulate.py", "test_derivatives.py",
              "test_gap_simulated.py", "test_dynamics_pinocchio.py", "test_urdf_parity.py", "test_docs.py")


def pytest_configure(config):
    if getattr(config.option, "dist", "no") == "loadfile":
        config.option.loadscopereorder = False  # the queue is the order pytest_collection_modifyitems leaves


def _queue_order(items):
    files: dict = {}
    for item in items:
        files.setdefault(item.path.name, []).append(item)
    rank = {name: k for k, name in enumerate(LONG_FILES)}
    order = sorted(files, key=lambda f: (rank.get(f, len(rank)), -len(files[f])))
    return [item for f in order for item in files[f]]


def pytest_collection_modifyitems(config, items):
    import pytest

    items[:] = _queue_order(items)

    # the installed wheel and the experiments' quick runs (minutes in all) run in CI's step of
    # their own (.ci/run), not in the suite
    if "experiments" not in (config.getoption("markexpr") or ""):
        skip = pytest.mark.skip(reason="an end-to-end run (an experiment, or jflex installed from a wheel): select it with -m experiments")
        for item in items:
            if "experiments" in item.keywords:
                item.add_marker(skip)
    if "long" not in (config.getoption("markexpr") or "") and not SLOW:
        skip = pytest.mark.skip(reason="a long end-to-end case, run in CI's step after the suite: select it with -m long "
                                       "(or JFLEX_SLOW=1)")
        for item in items:
            if "long" in item.keywords:
                item.add_marker(skip)
    if SLOW:
        return
    skip = pytest.mark.skip(reason="heavy case: set JFLEX_SLOW=1 to run it")
    for item in items:
        if "heavy" in item.keywords:
            item.add_marker(skip)
