"""Check that a refactoring slice keeps the Verilog and the renders bit for bit: hash the
Verilog of every unit, and the images, ids and counters of a set of bench renders, in the
working tree (or a ``--head`` commit) and in a base commit, and compare.

Each unit the ``verilog`` command emits is built at FP24 in every rounding, at its default
options and at each option that changes its datapath (``--target virtex4``,
``--adder virtex4``, ``--mode certified``, ``--reduce``), through
``raplas_hdl.pnr.unit.unit_verilog`` (what ``raplas-hdl verilog`` and ``pnr`` emit). The base
commit is checked out in a temporary ``git worktree`` and run by the same interpreter.

The renders (:data:`_RENDERS`): the procedural ``soup`` and ``cornell`` scenes at 32x32,
4x4 tiles, 2x2 shadow bundles and one secondary generation, through the float64 backend and
the model in the paper, conservative and certified modes and with the on-chip reduction;
each is hashed as its image, triangle ids, distances, visibility, secondary layers and
statistics (the unit's counters, the hierarchy's, the ray types'; not their wall times). A
render's first run in a fresh tree compiles its numba kernels (minutes; cached after).

Usage::

    python tools/compare_slice.py [--base HEAD] [--head REV] [--quick] [--only verilog|renders]

Prints one line per differing item and exits 1 if any differs, 0 if all are identical.
``--quick``: rtz only and no board top for the Verilog, the soup scene only for the renders.
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


#: Run inside the tree being compared; prints a JSON object of render hashes.
_RENDERS = r"""
import hashlib, json, sys, warnings
import numpy as np
warnings.simplefilter("ignore")
from raplas_hdl.fp import FP24
from raplas_hdl.host.backends import make_backend
from raplas_hdl.host.render import RenderSettings, render
from raplas_hdl.host.scenes import get_scene
quick = sys.argv[1] == "1"
scenes = [("soup", {"n": 60})] + ([] if quick else [("cornell", {"subdiv": 2})])
backends = [("float64", {}), ("model", {"mode": "paper"}), ("model", {"mode": "conservative"}),
            ("model", {"mode": "certified"}), ("model", {"mode": "paper", "reduce": True})]
settings = RenderSettings(width=32, height=32, rows=4, cols=4, shadow_rows=2, shadow_cols=2,
                          depth=1, progress=False, threads=1)
def untimed(d):
    # the statistics without their wall times (``exact_s``, ...: not part of the result)
    return {k: untimed(v) if isinstance(v, dict) else v for k, v in d.items()
            if not (k.endswith("_s") or k.endswith("seconds"))}
out = {}
for name, opts in scenes:
    scene = get_scene(name, **opts)
    for backend, kw in backends:
        r = render(scene, make_backend(backend, FP24, **kw), settings)
        h = hashlib.sha256()
        for a in (r.image, r.tri_id, r.t, r.visibility,
                  *(r.layers[k] for k in sorted(r.layers))):
            h.update(np.ascontiguousarray(a).tobytes())
        h.update(json.dumps(untimed(r.stats), sort_keys=True, default=str).encode())
        out[f"render {name} {backend} {json.dumps(kw, sort_keys=True)}"] = h.hexdigest()
print(json.dumps(out))
"""


def manifest(tree: Path, quick: bool, what: str) -> dict:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    proc = subprocess.run([sys.executable, "-c", _MANIFEST if what == "verilog" else _RENDERS,
                           "1" if quick else "0"], cwd=tree, env=env, capture_output=True,
                          text=True)
    if proc.returncode != 0:
        sys.exit(f"compare_slice: hashing the {what} of {tree} failed:\n"
                 f"{proc.stderr[-2000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def manifests(tree: Path, quick: bool, only: str | None) -> dict:
    out = {}
    for what in ("verilog", "renders"):
        if only in (None, what):
            out.update(manifest(tree, quick, what))
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--base", default="HEAD", help="the commit to compare with (default HEAD)")
    p.add_argument("--head", default=None,
                   help="the commit to check (default the working tree)")
    p.add_argument("--quick", action="store_true",
                   help="Verilog in rtz only without the board top; the soup scene only")
    p.add_argument("--only", choices=("verilog", "renders"), default=None,
                   help="compare only the Verilog or only the renders")
    args = p.parse_args(argv)
    found = {}
    with tempfile.TemporaryDirectory(prefix="compare-slice-") as tmp:
        for side, rev in (("base", args.base), ("head", args.head)):
            if rev is None:
                found[side] = manifests(ROOT, args.quick, args.only)
                continue
            tree = Path(tmp) / side
            subprocess.run(["git", "worktree", "add", "--detach", "-q", str(tree), rev],
                           cwd=ROOT, check=True)
            try:
                found[side] = manifests(tree, args.quick, args.only)
            finally:
                subprocess.run(["git", "worktree", "remove", "--force", str(tree)], cwd=ROOT,
                               check=False)
    old, new = found["base"], found["head"]
    differ = sorted(k for k in old.keys() | new.keys() if old.get(k) != new.get(k))
    for key in differ:
        print(f"differs: {key}: {old.get(key, 'missing')[:16]} -> {new.get(key, 'missing')[:16]}")
    head = args.head or "the working tree"
    for kind, prefix in (("Verilog texts", False), ("renders", True)):
        keys = [k for k in new if k.startswith("render ") == prefix]
        if keys:
            same = sum(1 for k in keys if k not in differ)
            print(f"{same} of {len(keys)} {kind} of {head} identical to {args.base}")
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
