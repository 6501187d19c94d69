"""CSV data sets: the reader lives in :mod:`jflex.data`; re-exported here."""

from ..data._csv import DELIMITERS as DELIMITERS, Table as Table, csv_arrays as csv_arrays, read_csv as read_csv
