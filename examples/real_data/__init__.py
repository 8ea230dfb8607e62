"""The two conversions behind ``examples/convert_real_data.py``: ``kvlcc2`` (SSPA roll decay) and
``hovercraft_epfl`` (EPFL hovercraft runs; loading in ``hovercraft_epfl_load``), with the
paths, sample rates and writer they share in ``common``."""
