"""Applies the mutant named in ``HMOCAP_MUTANT`` in every Python process of a mutant check.

``test_mutants.run_under_mutant`` puts this folder on ``PYTHONPATH``, so the node and command
processes a catching test starts run the mutant too, not only the pytest process.
"""
import os
import sys
from pathlib import Path

if os.environ.get("HMOCAP_MUTANT"):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    import test_mutants

    test_mutants.apply_named_mutant()
