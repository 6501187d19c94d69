"""A case: its configuration (case.yaml), its data sets read through :mod:`jflex.data`, and `case init`."""
