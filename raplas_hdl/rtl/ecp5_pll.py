"""An ECP5 PLL (``EHXPLLL``) from a board's oscillator to the unit's clock.

:func:`pll_settings` chooses the dividers as Project Trellis' ``ecppll`` does: every input
divider whose phase detector runs at 3.125-400 MHz, every feedback divider 1-80 and output
divider 1-128 whose VCO runs at 400-800 MHz; the output nearest the one asked for wins, a
VCO nearest 600 MHz breaking ties. The feedback is the primary output (``FEEDBK_PATH``
``CLKOP``), so the output is the input over the input divider times the feedback divider.
The loop-filter attributes are ecppll's (``ICP_CURRENT`` 12, ``LPF_RESISTOR`` 8), and
``FREQUENCY_PIN_CLKI`` / ``FREQUENCY_PIN_CLKOP`` tell nextpnr the clocks, so the output's
timing constraint follows from the input's ``FREQUENCY`` in the ``.lpf``.

:class:`ECP5PLL` is the instance: ``clk_in`` in, ``clk_out`` and ``locked`` out. It is a
primitive of the ECP5 (Yosys' ``synth_ecp5`` maps it, nextpnr places it): the Amaranth
simulator cannot run it, and the simulated board (:mod:`raplas_hdl.rtl.serial_board`) has
none.
"""

from dataclasses import dataclass

from amaranth.hdl import Instance, Module
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

__all__ = ["PLLSettings", "pll_settings", "ECP5PLL", "PFD_MHZ", "VCO_MHZ", "OUT_MHZ"]

#: The phase detector's, the VCO's and the output's ranges (MHz), as ecppll takes them.
PFD_MHZ = (3.125, 400.0)
VCO_MHZ = (400.0, 800.0)
OUT_MHZ = (3.125, 400.0)


@dataclass(frozen=True)
class PLLSettings:
    """Dividers of one EHXPLLL output and the frequencies they give (MHz)."""

    f_in: float
    clki_div: int
    clkfb_div: int
    clkop_div: int

    @property
    def f_pfd(self) -> float:
        return self.f_in / self.clki_div

    @property
    def f_out(self) -> float:
        return self.f_pfd * self.clkfb_div

    @property
    def f_vco(self) -> float:
        return self.f_out * self.clkop_div

    def to_dict(self) -> dict:
        return {"f_in_mhz": self.f_in, "f_out_mhz": round(self.f_out, 6),
                "f_vco_mhz": round(self.f_vco, 6), "clki_div": self.clki_div,
                "clkfb_div": self.clkfb_div, "clkop_div": self.clkop_div}


def pll_settings(f_in: float, f_out: float) -> PLLSettings:
    """The dividers giving the output nearest ``f_out`` MHz from ``f_in`` MHz (module
    docstring); a one-line ``ValueError`` when either is outside the PLL's ranges."""
    for what, f, (lo, hi) in (("input", f_in, PFD_MHZ), ("output", f_out, OUT_MHZ)):
        if not lo <= f <= hi:
            raise ValueError(f"an ECP5 PLL {what} runs at {lo:g}-{hi:g} MHz, not {f:g}")
    best, best_key = None, None
    for clki_div in range(1, 129):
        pfd = f_in / clki_div
        if pfd < PFD_MHZ[0]:
            break
        if pfd > PFD_MHZ[1]:
            continue
        for clkfb_div in range(1, 81):
            out = pfd * clkfb_div
            for clkop_div in range(1, 129):
                vco = out * clkop_div
                if not VCO_MHZ[0] <= vco <= VCO_MHZ[1]:
                    continue
                key = (abs(out - f_out), abs(vco - 600.0))
                if best_key is None or key < best_key:
                    best_key = key
                    best = PLLSettings(f_in, clki_div, clkfb_div, clkop_div)
    if best is None:
        raise ValueError(f"no ECP5 PLL setting makes {f_out:g} MHz from {f_in:g} MHz")
    return best


def _mhz(f: float) -> str:
    return f"{f:.6f}".rstrip("0").rstrip(".")


class ECP5PLL(wiring.Component):
    """One EHXPLLL, primary output only, fed back from it.

    Parameters
    ----------
    settings : PLLSettings
        From :func:`pll_settings`.

    Members
    -------
    clk_in : In(1)
    clk_out, locked : Out(1)
    """

    clk_in: In(1)
    clk_out: Out(1)
    locked: Out(1)

    def __init__(self, settings: PLLSettings):
        if not isinstance(settings, PLLSettings):
            raise TypeError(f"settings must be a PLLSettings, not {settings!r}")
        self.settings = settings
        super().__init__()

    def elaborate(self, platform):
        m = Module()
        s = self.settings
        m.submodules.pll = Instance(
            "EHXPLLL",
            a_FREQUENCY_PIN_CLKI=_mhz(s.f_in), a_FREQUENCY_PIN_CLKOP=_mhz(s.f_out),
            a_ICP_CURRENT="12", a_LPF_RESISTOR="8", a_MFG_ENABLE_FILTEROPAMP="1",
            a_MFG_GMCREF_SEL="2",
            p_PLLRST_ENA="DISABLED", p_INTFB_WAKE="DISABLED", p_STDBY_ENABLE="DISABLED",
            p_DPHASE_SOURCE="DISABLED", p_OUTDIVIDER_MUXA="DIVA", p_OUTDIVIDER_MUXB="DIVB",
            p_OUTDIVIDER_MUXC="DIVC", p_OUTDIVIDER_MUXD="DIVD",
            p_CLKI_DIV=s.clki_div, p_CLKOP_ENABLE="ENABLED", p_CLKOP_DIV=s.clkop_div,
            p_CLKOP_CPHASE=s.clkop_div // 2, p_CLKOP_FPHASE=0, p_FEEDBK_PATH="CLKOP",
            p_CLKFB_DIV=s.clkfb_div,
            i_RST=0, i_STDBY=0, i_CLKI=self.clk_in, i_CLKFB=self.clk_out,
            i_PHASESEL0=0, i_PHASESEL1=0, i_PHASEDIR=1, i_PHASESTEP=1, i_PHASELOADREG=1,
            i_PLLWAKESYNC=0, i_ENCLKOP=0,
            o_CLKOP=self.clk_out, o_LOCK=self.locked)
        return m
