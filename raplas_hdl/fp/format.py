"""The floating-point format object shared by the golden model, the RTL and the host.

One :class:`FPFormat` describes a member of the family defined in
``docs/fp-format.md``: ``1 + exp_bits + man_bits`` bits, a hidden leading one,
no denormals (flush to zero), one canonical NaN, and one of three roundings.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace

__all__ = ["FPFormat", "check_format", "ROUNDINGS", "FP16", "FP20", "FP24", "FP32", "FLAG_OVERFLOW",
           "FLAG_UNDERFLOW", "FLAG_INVALID", "FLAG_NAMES", "PRESETS", "parse_format"]

#: Roundings of the contract: ``rtz`` (correct, toward zero: the default), ``rne``
#: (correct, to nearest even) and ``chop`` (the paper's truncating adder).
ROUNDINGS = ("rtz", "rne", "chop")

#: Event-flag bits, as packed in the ``uint8`` flag arrays of the model and the
#: ``flags`` ports of the RTL.
FLAG_OVERFLOW = 1
FLAG_UNDERFLOW = 2
FLAG_INVALID = 4
FLAG_NAMES = {FLAG_OVERFLOW: "overflow", FLAG_UNDERFLOW: "underflow", FLAG_INVALID: "invalid"}


@dataclass(frozen=True)
class FPFormat:
    """A floating-point format of the contract.

    Parameters
    ----------
    exp_bits : int
        Exponent bits ``E``, 2 to 11.
    man_bits : int
        Stored fraction bits ``M``, at least 1; ``1 + E + M`` must be at most 32.
    rounding : str
        ``"rtz"`` (default), ``"rne"`` or ``"chop"``.

    Raises
    ------
    ValueError
        Naming the parameter that is out of range.
    """

    exp_bits: int
    man_bits: int
    rounding: str = "rtz"

    def __post_init__(self):
        for name in ("exp_bits", "man_bits"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool):
                raise ValueError(f"{name} must be an integer, not {value!r}")
        if not 2 <= self.exp_bits <= 11:
            raise ValueError(f"exp_bits must be between 2 and 11, not {self.exp_bits}")
        if self.man_bits < 1:
            raise ValueError(f"man_bits must be at least 1, not {self.man_bits}")
        if self.width > 32:
            raise ValueError(
                f"man_bits={self.man_bits} with exp_bits={self.exp_bits} gives a width of "
                f"{self.width} bits; the width 1+exp_bits+man_bits must be at most 32")
        if self.rounding not in ROUNDINGS:
            raise ValueError(f"rounding must be one of {', '.join(ROUNDINGS)}, "
                             f"not {self.rounding!r}")

    # -- derived constants -------------------------------------------------------------
    @property
    def width(self) -> int:
        """Total width ``W = 1 + E + M``."""
        return 1 + self.exp_bits + self.man_bits

    @property
    def bias(self) -> int:
        return (1 << (self.exp_bits - 1)) - 1

    @property
    def emin(self) -> int:
        """Smallest unbiased exponent of a normal number (``1 - bias``)."""
        return 1 - self.bias

    @property
    def emax(self) -> int:
        """Largest unbiased exponent of a finite number."""
        return (1 << self.exp_bits) - 2 - self.bias

    @property
    def exp_max_field(self) -> int:
        """The all-ones exponent field (infinities and NaNs)."""
        return (1 << self.exp_bits) - 1

    @property
    def man_mask(self) -> int:
        return (1 << self.man_bits) - 1

    @property
    def sign_bit(self) -> int:
        return 1 << (self.width - 1)

    @property
    def mask(self) -> int:
        return (1 << self.width) - 1

    @property
    def inf(self) -> int:
        """Bit pattern of +infinity."""
        return self.exp_max_field << self.man_bits

    @property
    def nan(self) -> int:
        """Bit pattern of the canonical NaN (sign 0, fraction ``1 << (M-1)``)."""
        return self.inf | (1 << (self.man_bits - 1))

    @property
    def max_finite(self) -> int:
        """Bit pattern of the largest finite positive value."""
        return ((self.exp_max_field - 1) << self.man_bits) | self.man_mask

    @property
    def min_normal(self) -> int:
        """Bit pattern of the smallest positive normal value."""
        return 1 << self.man_bits

    @property
    def one(self) -> int:
        """Bit pattern of 1.0."""
        return self.bias << self.man_bits

    @property
    def ulp(self) -> float:
        """Relative unit in the last place, ``2**-M``."""
        return 2.0 ** -self.man_bits

    @property
    def max_value(self) -> float:
        return (2.0 - 2.0 ** -self.man_bits) * 2.0 ** self.emax

    @property
    def min_value(self) -> float:
        """Smallest positive normal value."""
        return 2.0 ** self.emin

    @property
    def name(self) -> str:
        """Short name such as ``e7m16-rtz``, used for build directories and reports."""
        return f"e{self.exp_bits}m{self.man_bits}-{self.rounding}"

    def with_rounding(self, rounding: str) -> FPFormat:
        return replace(self, rounding=rounding)

    def __str__(self):
        preset = {v: k for k, v in PRESETS.items()}.get(self.with_rounding("rtz"))
        base = preset or f"E{self.exp_bits}M{self.man_bits}"
        return f"{base}/{self.rounding}"


FP16 = FPFormat(5, 10)
FP20 = FPFormat(6, 13)
FP24 = FPFormat(7, 16)
FP32 = FPFormat(8, 23)
PRESETS = {"FP16": FP16, "FP20": FP20, "FP24": FP24, "FP32": FP32}


def check_format(fmt, name: str = "fmt") -> FPFormat:
    """``fmt`` if it is an :class:`FPFormat` (the one type check of every API).

    Raises
    ------
    ValueError
        Naming the argument and what it got.
    """
    if not isinstance(fmt, FPFormat):
        raise ValueError(f"{name} must be an FPFormat, not {fmt!r}")
    return fmt


def parse_format(text: str, rounding: str | None = None) -> FPFormat:
    """Parse a format name into a format.

    Accepted spellings (case-insensitive): a preset ``FP16``, ``FP20``, ``FP24``, ``FP32``
    or field widths ``eXmY`` (``X`` exponent, ``Y`` fraction bits), optionally followed by
    ``/`` or ``-`` and a rounding: ``FP24``, ``FP24/rtz``, ``fp24-rne``, ``e7m16``,
    ``e7m16-rne``, ``E7M16/chop`` (what ``str(fmt)`` gives) and ``fmt.name``. A rounding
    in the text and ``rounding`` must agree; with neither the rounding is ``rtz``.

    Raises
    ------
    ValueError
        One line naming the text and what is wrong with it: not a format, an unknown
        preset or rounding, field widths out of range, or two roundings that disagree.
    """
    if not isinstance(text, str):
        raise ValueError(f"format must be a string such as FP24 or e7m16-rne, not {text!r}")
    t = text.strip()
    if rounding is not None and rounding not in ROUNDINGS:
        raise ValueError(f"rounding must be one of {', '.join(ROUNDINGS)}, not {rounding!r}")
    m = re.fullmatch(r"(?i)(fp\d+|e\d+m\d+)(?:[/-]([a-z0-9_]*))?", t)
    if not m:
        raise ValueError(f"format {text!r} is not FP16, FP20, FP24, FP32 or eXmY, with an "
                         f"optional rounding (for example FP24/rtz or e7m16-rne)")
    head, tail = m.group(1), m.group(2)
    rnd = rounding
    if tail is not None:
        tail = tail.lower()
        if tail not in ROUNDINGS:
            raise ValueError(f"format {text!r}: rounding {tail!r} is not one of "
                             f"{', '.join(ROUNDINGS)}")
        if rnd is not None and rnd != tail:
            raise ValueError(f"format {text!r} names rounding {tail!r} but rounding={rnd!r}")
        rnd = tail
    rnd = rnd or "rtz"
    if head.upper() in PRESETS:
        return PRESETS[head.upper()].with_rounding(rnd)
    if head.upper().startswith("FP"):
        raise ValueError(f"format {text!r}: known presets are {', '.join(PRESETS)} "
                         "(or give the field widths as eXmY)")
    e, mb = re.fullmatch(r"(?i)e(\d+)m(\d+)", head).groups()
    try:
        return FPFormat(int(e), int(mb), rnd)
    except ValueError as exc:
        raise ValueError(f"format {text!r}: {exc}") from None
