"""Test-session setup.

The suite is dominated by XLA compilation of many small, distinct programs, not by running
them. LLVM's backend optimisation level 0 cuts that CPU time by about a third (measured on
tests/test_render.py) without changing results: floating-point semantics are set by XLA's
own flags, not by the LLVM pass pipeline. A user-provided XLA_FLAGS is respected.
"""

import os

if "xla_backend_optimization_level" not in os.environ.get("XLA_FLAGS", ""):
  os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "")
                             + " --xla_backend_optimization_level=0").strip()
