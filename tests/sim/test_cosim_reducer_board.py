"""``raplas-hdl cosim reducer`` and ``board-top`` (raplas_hdl/sim/cosim/reducer.py, board.py)
under Icarus: a small random run through the command matches the model, and one
simulation's results against an expectation with one field changed are exactly one
mismatch, shown field by field. The bad inputs are in ``tests/cli/test_errors.py``."""

import subprocess
import sys

import pytest

from raplas_hdl.fp import FP24
from raplas_hdl.sim.cosim import unit_cosim

#: small units: the reducer of tests/rtl/unit/test_reducer.py, a 2x2 board top
REDUCER = {"rows": 2, "cols": 4}
BOARD = {"rows": 2, "cols": 2, "tris_per_sphere": 2}


def cosim(*argv) -> tuple[int, str, str]:
    """Run ``raplas-hdl cosim`` as a process: (exit code, stdout, stderr)."""
    res = subprocess.run([sys.executable, "-m", "raplas_hdl", "cosim", *[str(a) for a in argv]],
                         capture_output=True, text=True, timeout=900, check=False)
    return res.returncode, res.stdout, res.stderr


def _options(opts: dict) -> list[str]:
    return [a for k, v in opts.items() for a in (f"--{k.replace('_', '-')}", str(v))]


def test_reducer_random_runs_match_the_model():
    rc, out, err = cosim("reducer", "--sim", "icarus", "--random", 20, "--seed", 3,
                         *_options(REDUCER))
    assert rc == 0, out + err
    assert out.startswith("reducer e7m16-rtz rows=2 cols=4 under icarus (batch harness): "
                          "20 random runs (seed 3) against the model\n"), out
    assert "cases: 20\nmismatches: 0\n" in out and "cases/s: " in out, out


def test_board_top_random_runs_match_the_model_and_read_back(tmp_path):
    vec = tmp_path / "board.vec"
    rc, out, err = cosim("board-top", "--sim", "icarus", "--random", 2, "--seed", 2,
                         "--write-vectors", vec, *_options(BOARD))
    assert rc == 0, out + err
    assert out.startswith("board-top e7m16-rtz rows=2 cols=2 tris_per_sphere=2 under icarus "
                          "(host driver): 2 random runs (seed 2) against the model\n"), out
    assert "cases: 2\nmismatches: 0\n" in out, out
    assert vec.read_text().startswith("# board-top e7m16-rtz rows=2 cols=2 ")
    rc, out, err = cosim("board-top", "--sim", "icarus", "--vectors", vec, *_options(BOARD))
    assert rc == 0 and "cases: 2\nmismatches: 0\n" in out, out + err


def _simulated(name, options, n, seed):
    u = unit_cosim(name, FP24, options)
    cases = u.random(n, seed)
    expected = u.expected(cases)
    got, info = u.simulate(cases, "icarus", valid_density=0.8, stall_density=0.3, seed=seed)
    assert info["n"] == n
    return u, cases, expected, got


@pytest.fixture(scope="module")
def reducer_run():
    return _simulated("reducer", REDUCER, 8, seed=5)


@pytest.fixture(scope="module")
def board_run():
    return _simulated("board-top", BOARD, 2, seed=4)


def _check_reported(u, cases, bad_expected, got, k, field):
    n, lines = u.report(cases, bad_expected, got, 5)
    assert n == 1, lines
    assert lines[0] == f"  {u.describe(cases, k)}", lines
    marked = [ln for ln in lines if ln.endswith("<- differs")]
    assert len(marked) == 1 and field in marked[0], lines


@pytest.mark.parametrize("k", [0, 3])
def test_reducer_changed_answer_is_one_mismatch(reducer_run, k):
    u, cases, expected, got = reducer_run
    assert u.report(cases, expected, got, 5) == (0, [])
    answers = [a.copy() for a in expected["answers"]]
    answers[k]["t"][-1] ^= 1
    _check_reported(u, cases, {"answers": answers}, got, k, " t ")


def test_board_top_changed_counter_is_one_mismatch(board_run):
    u, cases, expected, got = board_run
    assert u.report(cases, expected, got, 5) == (0, [])
    runs = list(expected["runs"])
    stream, counters = runs[1]
    runs[1] = (stream, {**counters, "spheres": counters["spheres"] + 1})
    _check_reported(u, cases, {**expected, "runs": runs}, got, 1, "counter spheres")

