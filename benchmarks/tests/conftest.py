"""Tests of the benchmark scripts (not of the package): run with ``pytest benchmarks/tests``.

The scripts are not a package; their folder goes on the import path here, so
that the tests import ``_baseline2d`` and load ``blind_eval.py`` from it.
"""

import sys
from pathlib import Path

BENCHMARKS = Path(__file__).resolve().parents[1]
if str(BENCHMARKS) not in sys.path:
    sys.path.insert(0, str(BENCHMARKS))
