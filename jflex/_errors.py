"""Errors a user can cause: each names the file, field or link at fault and what is expected."""

from __future__ import annotations


class JFlexError(Exception):
    """Base class of every error jflex raises for bad input."""


class ConfigError(JFlexError, ValueError):
    """A YAML config or a DH table is malformed."""


class URDFError(JFlexError, ValueError):
    """A URDF file is malformed or describes something jflex cannot model."""


class ShapeError(JFlexError, ValueError):
    """An array argument has the wrong shape (e.g. q of the wrong length)."""


class DataError(JFlexError, ValueError):
    """A data file (NPZ, CSV) is malformed: NaNs, mismatched lengths, bad time axis."""


class ParameterError(JFlexError, ValueError):
    """A physical parameter is non-physical (negative mass, non-positive stiffness, ...)."""


class SolverError(JFlexError, RuntimeError):
    """A numerical solver failed (max steps, NaN); the message says which and how to fix it."""
