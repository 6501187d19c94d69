"""The built-in case of ``jflex demo``: a 3-joint arm whose data hide a payload and Coulomb
friction at one joint. The case ships with the package (``jflex/data/demo_case``, made by
``benchmarks/gap/make_demo_case.py``); it is copied into the run folder and diagnosed end to end."""

from __future__ import annotations

import pathlib

from .._progress import stages
from ._diagnose import diagnose
from .report._report import write_report

DATA = pathlib.Path(__file__).resolve().parents[1] / "data"


def demo(out_dir, *, progress=True) -> pathlib.Path:
    """Copy the built-in case to ``out_dir/case``, diagnose it, write the report into ``out_dir``;
    the hidden truth is written to ``out_dir/truth.json`` only after the diagnosis.

    ``progress``: ``True`` shows the stage on stderr (when it is a terminal), ``False`` nothing,
    a ``callable(str)`` receives the stage lines.

    **Returns:** the path of ``report.md``.
    """
    import json
    import shutil

    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    folder = out / "case"
    with stages("demo", progress) as say:
        say("copying the built-in case")
        if folder.exists():
            shutil.rmtree(folder)
        shutil.copytree(DATA / "demo_case", folder)
        diag = diagnose(folder, progress=say)
        say("writing the report (report.md, report.html, plots)")
        path = write_report(diag, out)
    truth = json.loads((DATA / "demo_truth.json").read_text())
    (out / "truth.json").write_text(json.dumps(truth, indent=2))
    with path.open("a") as f:
        f.write("\n## The hidden truth of this demo case (revealed after the diagnosis)\n\n")
        for e in truth["effects"]:
            f.write(f"- {e['effect']}" + (f" at {e['joint']}" if e.get("joint") else "") + f": {e['params']}\n")
    return path
