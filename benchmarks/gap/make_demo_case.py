"""Regenerate the built-in case of ``jflex demo`` (shipped in ``jflex/data/demo_case``): a 3-joint
arm whose data hide a payload and Coulomb friction at one joint, made by the jflex-family
generator. The library never runs this; it ships the files.

    python benchmarks/gap/make_demo_case.py
"""

import pathlib
import shutil
import sys

HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from jflex_family import generate as G  # noqa: E402

DEST = HERE.parents[1] / "jflex" / "data" / "demo_case"


def main():
    if DEST.exists():
        shutil.rmtree(DEST)
    DEST.parent.mkdir(parents=True, exist_ok=True)
    folder = G.torque_case(DEST, "arm3", ["coulomb_friction", "payload"], seed=5, noise=0.01, nominal_friction=True)
    # the hidden truth ships beside the case, never inside it
    shutil.move(str(folder.parent / f"{folder.name}.truth.json"), DEST.parent / "demo_truth.json")
    print(f"wrote {DEST} ({sum(p.stat().st_size for p in DEST.iterdir()) / 1e3:.0f} kB)")


if __name__ == "__main__":
    main()
