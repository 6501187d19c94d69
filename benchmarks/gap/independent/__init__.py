"""An independent family of gap-diagnosis cases (issue 13 item 6): made with Pinocchio (every
rigid-body quantity), SciPy (integration, filtering, H1 estimation) and NumPy (noise), never with
jflex, so the bench measures the diagnosis rather than agreement with its own generator.

Not imported by the library. From a test or a script::

    sys.path.insert(0, "benchmarks/gap")
    from independent import make_case
    folder, truth = make_case(tmp_path / "null", kind="torque", robot="arm3", effects=(), seed=1, small=True)
"""

from .cases import IN_LIBRARY_FREQ, IN_LIBRARY_TORQUE, OUT_OF_LIBRARY, family, make_case, plan

__all__ = ["IN_LIBRARY_FREQ", "IN_LIBRARY_TORQUE", "OUT_OF_LIBRARY", "family", "make_case", "plan"]
