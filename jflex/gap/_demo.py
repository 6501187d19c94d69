"""The built-in case of ``jflex demo``: a 3-joint arm whose data hide a payload and Coulomb
friction at one joint; generated on the fly (no files needed), then diagnosed end to end."""

from __future__ import annotations

import pathlib

from . import _generate as G
from ._diagnose import diagnose
from ._report import write_report


def demo(out_dir, *, progress=print) -> pathlib.Path:
    """Build the built-in case under ``out_dir/case``, diagnose it, write the report into
    ``out_dir``; the hidden truth is written to ``out_dir/truth.json`` only after the diagnosis.

    **Returns:** the path of ``report.md``.
    """
    import json
    import shutil

    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    folder = G.torque_case(out / "case", "arm3", ["coulomb_friction", "payload"], seed=5, noise=0.01, nominal_friction=True)
    hidden = out / "case.truth.json"
    stash = out / ".truth.hidden"
    shutil.move(str(hidden), stash)  # out of the way while the diagnosis runs
    diag = diagnose(folder, progress=progress)
    path = write_report(diag, out)
    shutil.move(str(stash), out / "truth.json")
    truth = json.loads((out / "truth.json").read_text())
    with path.open("a") as f:
        f.write("\n## The hidden truth of this demo case (revealed after the diagnosis)\n\n")
        for e in truth["effects"]:
            f.write(f"- {e['effect']}" + (f" at {e['joint']}" if e.get("joint") else "") + f": {e['params']}\n")
    return path
