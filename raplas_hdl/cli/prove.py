"""``raplas-hdl prove UNIT``: prove an FP unit's Verilog equal to the contract for all inputs.

Exit codes: 0 proved, 1 counterexample, 3 unknown (the solver ran out of time), 2 a bad
command line (one line, before any work). See ``docs/formal.md``.
"""

from __future__ import annotations

import sys

from . import grammar as g

#: Units that can be proved so far.
PROVE_UNITS = ("fp-add", "fp-mul", "fp-le", "fp-lt", "fp-neg", "ray-triangle")

#: Exit code of an unknown result (0 proved, 1 counterexample, 2 usage).
EXIT_UNKNOWN = 3


def add_parser(subparsers):
    p = subparsers.add_parser(
        "prove", help="prove an FP unit's Verilog equal to the arithmetic contract for all "
                      "inputs (Yosys + z3)",
        description="Emit the unit's Verilog, turn it into an SMT-LIB model with Yosys, "
                    "unroll it over its latency with en=1 and rst=0, and prove with z3 that "
                    "o, flags and o_valid equal the contract of docs/fp-format.md for every "
                    "input. fp-add proves add and sub (sub is a free input); fp-le, fp-lt "
                    "and fp-neg are the ordered comparisons and the negation the "
                    "ray-triangle unit decides with (one register stage). fp-mul is "
                    "proved with the significand product cut to one uninterpreted function "
                    "on both sides (--method cut, the default) or as a chain: the N-stage "
                    "unit equals its 1-stage form, which equals the contract (--method "
                    "chain); --method control proves the stall and reset properties "
                    "instead (a stall holds every register, rst clears every valid, the "
                    "outputs depend on the registers alone), --method sby their port-level "
                    "form with SymbiYosys; --method netlist-ecp5 or netlist-xc4v (every unit) "
                    "proves the unit's synthesised netlist (synth_ecp5 as `pnr` places it, "
                    "synth_xilinx -family xc4v as `synth` counts it) equal to its RTL. "
                    "Prints proved, a "
                    "counterexample (operands, RTL, netlist, contract and golden model "
                    "results) or "
                    "'unknown after S s'; exit 0, 1 or 3. Work "
                    "files go to build/formal/ under the current directory. --target "
                    "virtex4 proves the DSP48 forms of fp-add (direct) and fp-mul (cut) "
                    "with Yosys's DSP48 model. ray-triangle (--method composition) proves "
                    "the unit's wiring (--mode paper or conservative, whose margins and "
                    "widened decision are stated too): with every operation an uninterpreted "
                    "function, its output register holds the contract's formula (t, u, v, "
                    "det, hit, IDs, flags and event counts); with the operations proved "
                    "apart, that is the unit.")
    p.add_argument("unit", type=g.choice(*PROVE_UNITS, what="unit"), metavar="UNIT",
                   help="unit to prove: " + ", ".join(PROVE_UNITS))
    g.add_format_option(p)
    p.add_argument("--stages", type=g.int_range(1, None, name="stages"), default=None,
                   metavar="N", help="pipeline stages (default: the unit's default, as "
                                     "`raplas-hdl verilog` builds it)")
    p.add_argument("--timeout", type=g.float_range(0, 86400, lo_open=True), default=300.0,
                   metavar="S", help="seconds for each solver call (default 300)")
    p.add_argument("--method", type=g.choice("direct", "cut", "chain", "control", "sby",
                                             "netlist-ecp5", "netlist-xc4v", "composition",
                                             what="method"),
                   default=None,
                   metavar="{direct,cut,chain,control,sby,netlist-ecp5,netlist-xc4v,"
                           "composition}",
                   help="fp-add: direct; fp-mul: cut (default), chain or direct (the "
                        "FloatingPoint contract with real multipliers: does not close at "
                        "FP24); control (both units): the stall and reset properties "
                        "instead of the datapath; sby (both units): their port-level form "
                        "checked by SymbiYosys; netlist-ecp5, netlist-xc4v (every unit): "
                        "the synthesised netlist equals the RTL; composition (ray-triangle): "
                        "its wiring around uninterpreted operations")
    p.add_argument("--target", type=g.choice("generic", "virtex4", what="target"),
                   default="generic", metavar="{generic,virtex4}",
                   help="unit target: virtex4 (fp-add, fp-mul) instantiates DSP48, proved "
                        "with Yosys's simulation model of it (default generic)")
    p.add_argument("--mode", type=g.choice("paper", "conservative", "certified",
                                           what="mode"),
                   default="paper", metavar="{paper,conservative,certified}",
                   help="ray-triangle only: the unit's mode (default paper; conservative "
                        "needs a format with at least 8 fraction bits; certified, its bounds "
                        "and outcome included, at most 9 exponent bits)")
    p.add_argument("--json", default=None, metavar="FILE.json",
                   help="also write the result record as JSON")
    return p


def check(args) -> None:
    from ..formal.prove import METHODS, TARGET_METHODS, default_stages
    from ..synth.yosys import yosys_command
    from .verilog import UNIT_LIMITS

    args.fmt = g.format_from_args(args)
    if args.target != "generic":
        allowed = TARGET_METHODS.get(args.unit, ())
        if not allowed:
            raise g.UsageError(f"{args.unit} has no --target (only fp-add and fp-mul have a "
                               "virtex4 form)")
        if args.method is not None and args.method not in allowed:
            raise g.UsageError(f"--target {args.target} of {args.unit} is proved by --method "
                               f"{' or '.join(allowed)}, not {args.method}")
    if args.mode != "paper" and args.unit != "ray-triangle":
        raise g.UsageError(f"{args.unit} has no --mode (only ray-triangle)")
    if args.mode == "certified":
        from ..model.certified import MAX_EXP_BITS

        if args.fmt.exp_bits > MAX_EXP_BITS:
            raise g.UsageError(f"--mode certified needs at most {MAX_EXP_BITS} exponent bits, "
                               f"not {args.fmt.exp_bits} ({args.fmt})")
    if args.mode == "conservative" and args.fmt.man_bits < 8:
        raise g.UsageError(f"--mode conservative needs at least 8 fraction bits, not "
                           f"{args.fmt.man_bits} ({args.fmt})")
    if args.unit == "ray-triangle":
        if args.stages is not None:
            raise g.UsageError("ray-triangle takes no --stages (its operations are the FP "
                               "units at their default stage counts)")
        lo = hi = 0
    elif args.unit not in UNIT_LIMITS["stages"]:
        if args.stages not in (None, 1):
            raise g.UsageError(f"{args.unit} has one register stage: leave --stages out")
        lo = hi = 1
    else:
        lo, hi, _ = UNIT_LIMITS["stages"][args.unit]
    if args.stages is not None and not lo <= args.stages <= hi:
        raise g.UsageError(f"--stages of {args.unit} must be {lo} to {hi}, not {args.stages}")
    if args.method is not None and args.method not in METHODS[args.unit]:
        raise g.UsageError(f"--method of {args.unit} must be "
                           f"{' or '.join(METHODS[args.unit])}, not {args.method}")
    if args.fmt.man_bits < 2:
        raise g.UsageError(f"--format {args.fmt}: the proof needs at least 2 fraction bits")
    if args.json:
        g.check_output_file(args.json, (".json",), "--json")
    args.stages = default_stages(args.unit, args.fmt) if args.stages is None else args.stages
    try:
        import z3  # noqa: F401
    except ModuleNotFoundError:
        raise g.UsageError("z3 is not installed: pip install z3-solver "
                           "(or `make setup`)") from None
    yosys_command()      # FileNotFoundError naming what to install
    if args.method == "sby":
        from ..formal.sby import sby_tools

        sby_tools()


def run(args) -> int:
    import json
    from pathlib import Path

    from ..formal.prove import describe, prove

    res = prove(args.unit, args.fmt, args.stages, method=args.method, timeout=args.timeout,
                target=args.target, mode=args.mode)
    plural = "" if res.stages == 1 else "s"
    head = (f"{args.unit} {args.fmt}, {args.mode} mode" if args.unit == "ray-triangle" else
            f"{args.unit} {args.fmt}, {res.stages} stage{plural}, {res.target}")
    if res.result == "proved":
        print(f"{head}: proved in {res.seconds:.1f} s by {res.method}")
    elif res.result == "counterexample":
        print(f"{head}: counterexample ({res.steps[-1]['proves']})")
        if args.unit == "ray-triangle":
            print("  claims that fail: " + ", ".join(
                k.removeprefix("fails.") for k in res.counterexample or {}))
        else:
            for line in describe(res, args.fmt):
                print(line)
    else:
        print(f"{head}: unknown after {res.seconds:.0f} s ({res.reason})")
    for step in res.steps:
        print(f"  {step['result']:<14} {step['seconds']:8.2f} s  {step['proves']}",
              file=sys.stderr)
    print(f"  solver: {res.solver}", file=sys.stderr)
    if args.json:
        Path(args.json).write_text(json.dumps(res.as_dict(), indent=1, sort_keys=True) + "\n")
    return {"proved": 0, "counterexample": 1}.get(res.result, EXIT_UNKNOWN)
