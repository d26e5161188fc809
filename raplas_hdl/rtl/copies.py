"""N copies of one unit side by side in one design (``raplas-hdl pnr UNIT --copies N``).

Place and route of one unit says how fast it runs alone; how many fit on a device, and at
what clock, needs them placed together. :class:`Copies` is a component with ``N`` instances
of a unit, each with its own ports (``u0``, ``u1``, ...: the unit's signature as it is, so the
Verilog ports are ``u0__a``, ``u1__a``, ...). Nothing is shared between the copies, so
synthesis cannot merge them.
"""

from __future__ import annotations

from collections.abc import Callable

from amaranth.hdl import Module
from amaranth.lib import wiring
from amaranth.lib.wiring import Out

__all__ = ["Copies", "MAX_COPIES"]

#: The most copies of a design (far above what fits: the LFE5U-85F has 156 multipliers).
MAX_COPIES = 256


class Copies(wiring.Component):
    """``n`` instances of the unit ``make()`` builds, each on its own ports.

    Parameters
    ----------
    make : callable
        Returns a new unit (an ``amaranth.lib.wiring.Component``) at each call.
    n : int
        Copies, 1 to :data:`MAX_COPIES`.

    Attributes
    ----------
    u0, u1, ... : Out(the unit's signature)
        The ports of each copy, as the unit's own.

    Raises
    ------
    ValueError
        If ``n`` is out of range or ``make`` does not return a component.
    """

    def __init__(self, make: Callable[[], wiring.Component], n: int):
        if not isinstance(n, int) or isinstance(n, bool) or not 1 <= n <= MAX_COPIES:
            raise ValueError(f"copies must be an integer from 1 to {MAX_COPIES}, not {n!r}")
        self._units = [make() for _ in range(n)]
        for u in self._units:
            if not isinstance(u, wiring.Component):
                raise ValueError(f"make() must return a wiring.Component, not {u!r}")
        super().__init__({f"u{i}": Out(u.signature) for i, u in enumerate(self._units)})

    @property
    def copies(self) -> int:
        return len(self._units)

    @property
    def latency(self):
        """The unit's latency (``None`` when it has none)."""
        return getattr(self._units[0], "latency", None)

    def elaborate(self, platform):
        m = Module()
        for i, unit in enumerate(self._units):
            m.submodules[f"unit_{i}"] = unit
            wiring.connect(m, wiring.flipped(getattr(self, f"u{i}")), unit)
        return m
