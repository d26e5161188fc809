"""Issue 11, point 3: `--waves` records an FST waveform of every simulation of a command and
prints its path (Icarus: cocotb's dump module with `-fst`; Verilator: `--trace-fst`).

One small cosim per simulator (a simulator build each: about 30 s under Verilator)."""

import pytest

from raplas_hdl.cli import main
from raplas_hdl.sim.build.runner import available_simulators

FST_MAGIC = bytes([0])   # an FST file starts with a header block of type 0 (VCD with '$')


@pytest.mark.parametrize("sim", ["icarus", "verilator"])
def test_cosim_waves_write_fst_and_print_the_path(tmp_path, capsys, sim):
    if sim not in available_simulators():
        pytest.skip(f"{sim} is not installed")
    from raplas_hdl.cli.grammar import fst_libs_missing

    if sim == "verilator" and fst_libs_missing():
        pytest.skip(f"Verilator FST needs {fst_libs_missing()} (apt-get install liblz4-dev)")
    waves = tmp_path / "waves"
    assert main(["cosim", "fp-mul", "--sim", sim, "--random", "64", "--format", "FP16",
                 "--waves", "--waves-dir", str(waves)]) == 0
    out, err = capsys.readouterr()
    assert "mismatches: 0" in out
    files = sorted(waves.glob("*.fst"))
    assert len(files) == 1 and files[0].stat().st_size > 0
    assert f"waveform: {files[0]}" in err
    head = files[0].read_bytes()[:1]
    assert head == FST_MAGIC, f"{files[0]} is not FST (starts with {head!r})"
