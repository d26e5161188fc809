"""``raplas-hdl cosim`` for every unit, under Icarus and Verilator, against the golden model.

Each unit runs once per simulator through the CLI (one test each: one build per unit,
format and simulator, cached under ``build/sim``): random cases with zero mismatches, the
cases written with ``--write-vectors`` and read back with ``--vectors`` (zero mismatches
again, the same build), and the same file with one expected field changed: exit 1, one
mismatch, printed field by field. Every output bit is compared (the CLI's
comparison; the corrupted file shows it can fail). The errors (a bad line, a header for
another unit or parameters, an option the unit does not take) are one line before any
work. The ``full`` marker adds larger runs at FP24 (both ray-triangle modes, the paper's
4x4 array, time-shared arrays, more intersection runs).
"""

from __future__ import annotations

import re
import subprocess
import sys

import pytest

SIMS = ("icarus", "verilator")

#: unit -> (options, --random in make test); small formats keep the builds short.
UNITS = {
    "fp-add": (["--format", "FP16", "--stages", "3"], 3000),
    "fp-mul": (["--format", "FP16", "--target", "virtex4"], 3000),
    "plane-sphere-tester": (["--format", "e5m6"], 3000),
    "plane-sphere": (["--format", "e5m6", "--rows", "2", "--cols", "3", "--testers", "2"], 400),
    "ray-triangle": (["--format", "e5m10", "--mode", "conservative"], 600),
    # Verilator: sim/test_unit_harness.py's unit (one build serves both); Icarus runs the whole
    # unit at a few hundred clocks per second, so a 2x2 unit with short lists there
    "intersection-unit": (["--testers", "4", "--tris-per-sphere", "4"], 3),
}
OPTIONS_ICARUS = {"intersection-unit": (["--rows", "2", "--cols", "2", "--tris-per-sphere", "2"],
                                        2)}


def cosim(*argv) -> tuple[int, str, str]:
    """Run ``raplas-hdl cosim`` as a process: (exit code, stdout, stderr)."""
    res = subprocess.run([sys.executable, "-m", "raplas_hdl", "cosim", *[str(a) for a in argv]],
                         capture_output=True, text=True, timeout=900, check=False)
    return res.returncode, res.stdout, res.stderr


def _ok(rc, out, err, n):
    assert rc == 0, out + err
    assert f"cases: {n}\n" in out and "mismatches: 0\n" in out, out
    assert re.search(r"cases/s: [\d,.]+", out), out


def _corrupt(path, unit) -> tuple[str, str]:
    """Change one expected field of the vectors file at ``path``; (new path, field)."""
    lines = path.read_text().splitlines()
    tag, field_index, name = {
        "fp-add": (None, 3, "o"), "fp-mul": (None, 2, "o"),
        "plane-sphere-tester": ("S", 5, "flag"), "plane-sphere": ("S", 6, "row_mask"),
        "ray-triangle": (None, 21, "t"), "intersection-unit": ("CTR", 1, "spheres"),
    }[unit]
    for k, line in enumerate(lines):
        f = line.split()
        if not f or f[0].startswith("#") or (tag is not None and f[0] != tag):
            continue
        v = int(f[field_index], 16)
        f[field_index] = f"{v ^ 1:x}"
        lines[k] = " ".join(f)
        break
    bad = path.with_name("bad-" + path.name)
    bad.write_text("\n".join(lines) + "\n")
    return bad, name


# One test per unit and simulator (not three on a module fixture): pytest-xdist would run
# such a fixture once on each worker that draws one of its tests.
@pytest.mark.parametrize("unit, sim", [(u, s) for u in UNITS for s in SIMS],
                         ids=[f"{u}-{s}" for u in UNITS for s in SIMS])
def test_cosim_random_written_and_changed_vectors(unit, sim, tmp_path):
    opts, n = OPTIONS_ICARUS.get(unit, UNITS[unit]) if sim == "icarus" else UNITS[unit]
    vec = tmp_path / "cases.vec"
    # random cases with zero mismatches
    first = cosim(unit, "--sim", sim, "--random", n, "--seed", 3, "--write-vectors", vec, *opts)
    _ok(*first, n)
    assert first[1].startswith(unit)
    # the written cases read back: zero mismatches again
    head = vec.read_text().splitlines()[0]
    assert head.startswith(f"# {unit} "), head
    _ok(*cosim(unit, "--sim", sim, "--vectors", vec, "--seed", 4, *opts), n)
    # one expected field changed: one mismatch, shown field by field
    path, name = _corrupt(vec, unit)
    rc, out, err = cosim(unit, "--sim", sim, "--vectors", path, *opts)
    assert rc == 1, out + err
    assert "mismatches: 1\n" in out, out
    marked = [ln for ln in out.splitlines() if ln.rstrip().endswith("<- differs")]
    assert len(marked) == 1 and name in marked[0], out


def test_waves_of_a_unit_run(tmp_path):
    waves = tmp_path / "w"
    rc, out, err = cosim("plane-sphere-tester", "--sim", "icarus", "--format", "e5m6",
                         "--random", 200, "--waves", "--waves-dir", waves)
    _ok(rc, out, err, 200)
    files = sorted(waves.glob("*.fst"))
    assert len(files) == 1 and files[0].stat().st_size > 0
    assert f"waveform: {files[0]}" in err


def test_tester_virtex4_dsp48_model(tmp_path):
    rc, out, err = cosim("plane-sphere-tester", "--sim", "icarus", "--format", "FP24",
                         "--target", "virtex4", "--random", 1500)
    _ok(rc, out, err, 1500)
    assert "target=virtex4 latency 18" in out


# -- errors: one line, exit 2, before any simulation -----------------------------------------

def _write(path, text):
    path.write_text(text)
    return path


ERRORS = [
    ("ray-triangle-field-count", ["ray-triangle"], "1 2 3\n",
     ["t.vec:1", "a ray-triangle line has 29 hex fields", "not 3"]),
    ("tester-not-hex", ["plane-sphere-tester"], "P 1 2 3 4\nS 1 2 3 zz 1\n",
     ["t.vec:2", "not a hex number"]),
    ("tester-too-wide", ["plane-sphere-tester", "--format", "e5m6"],
     "P 1 2 3 4\nS 1 2 3 4 2\n", ["t.vec:2", "FLAG 0x2 is wider than its 1 bits"]),
    ("tester-sphere-before-plane", ["plane-sphere-tester"], "S 1 2 3 4 1\n",
     ["t.vec:1", "a sphere before 1 P lines"]),
    ("array-unknown-kind", ["plane-sphere"], "Q 1 2\n", ["unknown line kind 'Q'", "P or S"]),
    ("array-header-other-unit", ["plane-sphere"],
     "# ray-triangle e7m16-rtz mode=paper: ...\n", [("holds ray-triangle vectors, not "
                                                    "plane-sphere")]),
    ("array-header-other-rows", ["plane-sphere"],
     "# plane-sphere e7m16-rtz rows=3 cols=4: ...\n",
     ["the file is for rows=3, not rows=4", "give --rows 3"]),
    ("ray-triangle-header-other-mode", ["ray-triangle"],
     "# ray-triangle e7m16-rtz mode=conservative: ...\n", ["give --mode conservative"]),
    ("intersection-run-before-bundle", ["intersection-unit"], "RUN 0 0 1\n",
     ["RUN names bundle 0", "has 0"]),
    ("intersection-no-scene", ["intersection-unit"], "B\n", ["no scene (T and S lines)"]),
]


@pytest.mark.parametrize("argv, text, needles", [e[1:] for e in ERRORS],
                         ids=[e[0] for e in ERRORS])
def test_bad_vectors_file(tmp_path, argv, text, needles):
    f = _write(tmp_path / "t.vec", text)
    rc, out, err = cosim(*argv, "--sim", "icarus", "--vectors", f)
    assert rc == 2 and out == "", out
    assert err.count("\n") == 1 and err.startswith("raplas-hdl cosim: error:"), err
    for s in needles:
        assert s in err, err


@pytest.mark.parametrize("argv, needle", [
    (["ray-triangle", "--rows", "2"], "--rows does not apply to unit ray-triangle"),
    (["plane-sphere", "--mode", "conservative"], "--mode does not apply to unit plane-sphere"),
    (["fp-mul", "--adder", "virtex4"], "--adder does not apply to unit fp-mul"),
    (["ray-triangle", "--adder", "virtex4", "--format", "FP32"], "at most 17 bits"),
    (["plane-sphere", "--rows", "2", "--cols", "2", "--testers", "5"],
     "--testers 5 is more than rows+cols = 4"),
    (["ray-triangle", "--driver", "percycle"], "--driver percycle applies to fp-add and fp-mul"),
    (["ray-triangle", "--mode", "percycle"], "applies to fp-add and fp-mul only"),
    (["intersection-unit", "--valid-density", "0.5"], "--valid-density does not apply"),
    (["intersection-unit", "--random", "200000"], "at most 100,000 runs"),
    (["ray-triangle", "--format", "e4m3", "--mode", "conservative"], "man_bits"),
])
def test_option_errors(argv, needle):
    rc, out, err = cosim(*argv, "--sim", "icarus")
    assert rc == 2 and out == "", out
    assert err.count("\n") == 1 and needle in err, err


def test_intersection_unit_virtex4_target():
    """The whole unit with its multipliers in DSP48 primitives (Yosys's model), Icarus,
    a 2x2 unit: zero mismatches against the model."""
    rc, out, err = cosim("intersection-unit", "--sim", "icarus", "--target", "virtex4",
                         "--format", "e5m6", "--rows", "2", "--cols", "2",
                         "--tris-per-sphere", "2", "--random", 2, "--seed", 5)
    _ok(rc, out, err, 2)


# -- full: larger runs -------------------------------------------------------------------

FULL = [
    ("ray-triangle", ["--mode", "paper"], 200_000, 20_000),
    ("ray-triangle", ["--mode", "conservative", "--format", "FP24/rne"], 200_000, 20_000),
    ("plane-sphere", [], 100_000, 10_000),
    ("plane-sphere", ["--rows", "5", "--cols", "6", "--testers", "4"], 50_000, 5_000),
    ("plane-sphere-tester", ["--target", "virtex4"], 1_000_000, 50_000),
    ("intersection-unit", ["--rows", "8", "--cols", "8"], 64, 8),
    ("fp-mul", ["--target", "virtex4"], 1_000_000, 100_000),
]


@pytest.mark.full
@pytest.mark.parametrize("sim", SIMS)
@pytest.mark.parametrize("unit, opts, n_verilator, n_icarus", FULL,
                         ids=[f"{u}-{'-'.join(o) or 'default'}" for u, o, _, _ in FULL])
def test_full(sim, unit, opts, n_verilator, n_icarus):
    n = n_verilator if sim == "verilator" else n_icarus
    _ok(*cosim(unit, "--sim", sim, "--random", n, "--seed", 11, *opts), n)
