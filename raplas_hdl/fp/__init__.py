"""Floating-point format family of the contract (``docs/fp-format.md``).

``raplas_hdl.fp`` holds the format object; ``raplas_hdl.fp.model`` the bit-exact golden
model. Neither imports Amaranth.
"""

from .format import (FLAG_INVALID, FLAG_NAMES, FLAG_OVERFLOW, FLAG_UNDERFLOW, FP16, FP20,
                     FP24, FP32, PRESETS, ROUNDINGS, FPFormat, check_format, parse_format)

__all__ = ["FPFormat", "check_format", "ROUNDINGS", "FP16", "FP20", "FP24", "FP32", "PRESETS",
           "parse_format", "FLAG_OVERFLOW", "FLAG_UNDERFLOW", "FLAG_INVALID", "FLAG_NAMES"]
