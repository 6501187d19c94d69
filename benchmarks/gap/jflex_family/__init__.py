"""The jflex-made family of the gap bench (cases generated with jflex's own kernels, and a MuJoCo
family): outside the library's import graph. The independent family is ``../independent``.

From a test or a script::

    sys.path.insert(0, "benchmarks/gap")
    from jflex_family import generate, bench
"""
