"""The cocotb test modules, loaded by the simulator from the dotted names passed to
:func:`raplas_hdl.sim.build.runner.run_cocotb`; each holds only what the simulator loads
(the pytest side lives in :mod:`raplas_hdl.sim.drive` and :mod:`raplas_hdl.sim.cosim`)."""
