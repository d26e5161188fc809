"""Where the package writes what it builds (simulator models, Yosys results), and where
the files it ships (meshes, scene files) are.

``build/`` of the checkout when the package runs from one (an editable install: the tests
and the Makefile's targets); else ``build/`` of the working directory (an installed wheel:
never inside site-packages). The commands' own outputs (``build/demo``, ``build/verilog``,
...) are relative to the working directory as given.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["DATA_DIR", "build_root", "shipped"]

#: The package's shipped data (``raplas_hdl/data``: meshes, scene files).
DATA_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data")


def build_root() -> Path:
    """The ``build`` folder (module docstring); not created here."""
    checkout = Path(__file__).resolve().parents[1]
    if (checkout / "pyproject.toml").is_file() and (checkout / "raplas_hdl").is_dir():
        return checkout / "build"
    return Path.cwd().resolve() / "build"


def shipped(folder: str, suffixes) -> dict:
    """The files of ``folder`` with one of ``suffixes``, by stem, sorted (empty when the
    folder does not exist)."""
    return {os.path.splitext(f)[0]: os.path.join(folder, f)
            for f in sorted(os.listdir(folder)) if os.path.splitext(f)[1] in suffixes} \
        if os.path.isdir(folder) else {}
