"""FRF data sets as UFF 58 files: the reader lives in :mod:`jflex.data`; re-exported here."""

from ..data._uff import AXES as AXES, FRF_FUNCTION as FRF_FUNCTION, QUANTITY_UNITS as QUANTITY_UNITS
from ..data._uff import uff_arrays as uff_arrays
