"""Test set-up: the repository root on ``sys.path``, and the common kernels compiled once.

Under pytest-xdist every worker would compile the same numba kernels at the same time;
:func:`raplas_hdl.host.warm.warm` compiles them under a file lock, so the first worker
compiles and the others load numba's disk cache.
"""

import os
import sys

import pytest

_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if _ROOT not in sys.path:
    sys.path.insert(0, _ROOT)


@pytest.fixture(scope="session", autouse=True)
def _compiled_once():
    from raplas_hdl.host.warm import default_lock, warm

    warm(lock=default_lock())
