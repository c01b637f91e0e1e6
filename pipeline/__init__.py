"""The ORCa pipeline: stages from photos to results, their artifacts, and the ``orca`` CLI.

The method itself lives in :mod:`orca` and knows nothing about folders; this package reads and writes
files and calls into it.
"""

__version__ = "0.1.0"
