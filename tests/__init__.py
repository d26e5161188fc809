"""The tests, laid out like the package: ``tests/<layer>/`` checks ``raplas_hdl/<layer>/``.

- ``fp``, ``model``, ``engine``, ``rtl`` (``rtl/unit``: the intersection unit's stages),
  ``sim``, ``synth``, ``pnr``, ``formal``, ``host``, ``verify``, ``bench``, ``cli``: each
  test module sits beside the code it mainly checks; a unit's RTL against its golden model
  (in Amaranth's simulator or as Verilog under cocotb) is an ``rtl`` test;
- ``project``: the package's top-level modules (``cluster``) and repository-wide checks
  (the wheel and the public API, the CI workflow, the FuseSoC cores, docs/cli.md);
- ``support``: what several test modules share (oracles, stimulus, scenes, testbenches);
  no test module imports another test module.

Every folder is a package, so test modules are imported as ``tests.<layer>.<module>``.
"""
