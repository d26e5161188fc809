"""Check that a refactoring slice keeps the Verilog bit for bit: hash the Verilog of every unit
in the working tree and in a base commit, and compare.

Each unit the ``verilog`` command emits is built at FP24 in every rounding, at its default
options and at each option that changes its datapath (``--target virtex4``,
``--adder virtex4``, ``--mode certified``, ``--reduce``), through
``raplas_hdl.pnr.unit.unit_verilog`` (what ``raplas-hdl verilog`` and ``pnr`` emit). The base
commit is checked out in a temporary ``git worktree`` and run by the same interpreter.

Usage::

    python tools/compare_slice.py [--base HEAD] [--quick]

Prints one line per differing unit and exits 1 if any differs, 0 if all are identical.
``--quick``: rtz only, and no board top.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: Run inside the tree being hashed (its own raplas_hdl on sys.path); prints a JSON object.
_MANIFEST = r"""
import hashlib, json, sys, warnings
warnings.simplefilter("ignore")
from raplas_hdl.cli.verilog import CHOICE_OPTIONS, FLAG_OPTIONS, UNIT_NAMES
from raplas_hdl.fp import FP24
from raplas_hdl.pnr.unit import unit_verilog
quick = sys.argv[1] == "1"
out = {}
for unit in UNIT_NAMES:
    if quick and unit == "board-top":
        continue
    variants = [{}]
    for opt, value in (("target", "virtex4"), ("adder", "virtex4"), ("mode", "certified")):
        if unit in CHOICE_OPTIONS.get(opt, ((), None, ()))[2]:
            variants.append({opt: value})
    if unit in FLAG_OPTIONS.get("reduce", ()):
        variants.append({"reduce": True})
    for rounding in (("rtz",) if quick else ("rtz", "rne", "chop")):
        for opts in variants:
            key = f"{unit} {rounding} {json.dumps(opts, sort_keys=True)}"
            try:
                text, _, _ = unit_verilog(unit, FP24.with_rounding(rounding), opts, 1)
                out[key] = hashlib.sha256(text.encode()).hexdigest()
            except Exception as e:      # a refusal is compared like a text
                out[key] = f"refused: {type(e).__name__}: {e}"
print(json.dumps(out))
"""


def manifest(tree: Path, quick: bool) -> dict:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    proc = subprocess.run([sys.executable, "-c", _MANIFEST, "1" if quick else "0"], cwd=tree,
                          env=env, capture_output=True, text=True)
    if proc.returncode != 0:
        sys.exit(f"compare_slice: hashing {tree} failed:\n{proc.stderr[-2000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--base", default="HEAD", help="the commit to compare with (default HEAD)")
    p.add_argument("--quick", action="store_true", help="rtz only, no board top")
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="compare-slice-") as tmp:
        base = Path(tmp) / "base"
        subprocess.run(["git", "worktree", "add", "--detach", "-q", str(base), args.base],
                       cwd=ROOT, check=True)
        try:
            old = manifest(base, args.quick)
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(base)], cwd=ROOT,
                           check=False)
    new = manifest(ROOT, args.quick)
    differ = sorted(k for k in old.keys() | new.keys() if old.get(k) != new.get(k))
    for key in differ:
        print(f"differs: {key}: {old.get(key, 'missing')[:16]} -> {new.get(key, 'missing')[:16]}")
    print(f"{len(new) - len(differ)} of {len(new)} Verilog texts identical to {args.base}")
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
