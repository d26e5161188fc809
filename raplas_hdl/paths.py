"""Where the package writes what it builds (simulator models, Yosys results).

``build/`` of the checkout when the package runs from one (an editable install: the tests
and the Makefile's targets); else ``build/`` of the working directory (an installed wheel:
never inside site-packages). The commands' own outputs (``build/demo``, ``build/verilog``,
...) are relative to the working directory as given.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["build_root"]


def build_root() -> Path:
    """The ``build`` folder (module docstring); not created here."""
    checkout = Path(__file__).resolve().parents[1]
    if (checkout / "pyproject.toml").is_file() and (checkout / "raplas_hdl").is_dir():
        return checkout / "build"
    return Path.cwd().resolve() / "build"
