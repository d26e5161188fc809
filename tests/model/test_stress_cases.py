"""The seeded hard-case families of :mod:`raplas_hdl.model.stress_cases`."""

import pytest

from raplas_hdl.fp import FP24
from raplas_hdl.model.stress_cases import generate


def test_generator_is_seeded():
    a = generate(FP24, 5, seed=9)
    b = generate(FP24, 5, seed=9)
    c = generate(FP24, 5, seed=10)
    assert (a.o == b.o).all() and (a.v2 == b.v2).all()
    assert not (a.o == c.o).all()


def test_unknown_family():
    with pytest.raises(ValueError, match="family"):
        generate(FP24, 5, families=("random", "bogus"))
