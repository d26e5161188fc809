"""The GitHub Actions workflow runs the project's CI script on Ubuntu with Python 3.11 and
caches pip's downloads and the simulator builds."""

from __future__ import annotations

import subprocess
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[2]
WORKFLOW = ROOT / ".github" / "workflows" / "ci.yml"


def _workflow() -> dict:
    return yaml.safe_load(WORKFLOW.read_text())


def _steps():
    jobs = _workflow()["jobs"]
    assert len(jobs) == 1
    job = next(iter(jobs.values()))
    return job, job["steps"]


def test_triggers():
    doc = _workflow()
    triggers = doc.get("on", doc.get(True))   # YAML 1.1 reads a bare `on` as true
    assert {"push", "pull_request"} <= set(triggers)


def test_runs_ci_script_on_ubuntu_with_python_311():
    job, steps = _steps()
    assert job["runs-on"].startswith("ubuntu")
    assert job["timeout-minutes"] <= 90
    uses = [s.get("uses", "") for s in steps]
    assert any(u.startswith("actions/checkout@") for u in uses)
    setup = [s for s in steps if s.get("uses", "").startswith("actions/setup-python@")]
    assert len(setup) == 1 and str(setup[0]["with"]["python-version"]) == "3.11"
    runs = [s["run"].strip() for s in steps if "run" in s]
    assert runs[-1] == "bash .ci/run"
    assert (ROOT / ".ci" / "run").is_file()
    # the runner is not root: the system tools tools/bootstrap.py would apt-get come first
    tools = " ".join(runs[:-1])
    for pkg in ("iverilog", "g++", "make", "liblz4-dev"):
        assert pkg in tools, pkg


def test_caches_pip_and_simulator_builds():
    _, steps = _steps()
    caches = [s for s in steps if s.get("uses", "").startswith("actions/cache@")]
    paths = {s["with"]["path"].strip(): s["with"]["key"] for s in caches}
    assert set(paths) == {"~/.cache/pip", "build/sim"}
    assert "requirements.lock" in paths["~/.cache/pip"]
    assert "raplas_hdl/**/*.py" in paths["build/sim"]
    ci = [i for i, s in enumerate(steps) if s.get("run", "").strip() == "bash .ci/run"][0]
    assert all(steps.index(s) < ci for s in caches)


def test_shared_guard_passes_here():
    """The workflow's guard step (nothing reads the steering folder beside the clone) runs
    and passes on this checkout."""
    _, steps = _steps()
    guard = [s for s in steps if "git grep" in s.get("run", "")]
    assert len(guard) == 1
    res = subprocess.run(["bash", "-e", "-c", guard[0]["run"]], cwd=ROOT, capture_output=True,
                         text=True)
    assert res.returncode == 0, res.stdout + res.stderr
