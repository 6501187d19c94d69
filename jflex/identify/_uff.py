"""Universal File Format dataset 58: the reader lives in :mod:`jflex.data` (one reader for
identification and the gap diagnosis); re-exported here."""

from ..data._uff import FUNCTION_TYPES as FUNCTION_TYPES, UFF58 as UFF58, read_uff58 as read_uff58
from ..data._uff import write_uff58 as write_uff58
