"""Effects added to the rigid core of a model: one file per family."""

from ._base import AbstractEffect as AbstractEffect, Slots as Slots
