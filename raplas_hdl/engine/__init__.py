"""The engine: whole passes of bundles through compiled code, for the model and float64.

- :mod:`raplas_hdl.engine.kernels`: the compiled kernels (hierarchy cull, unit runs reduced
  to nearest hits), one set per format, rounding and mode for the model, one for float64;
- :mod:`raplas_hdl.engine.passes`: a pass as arrays (:class:`~.passes.BundleBatch`), the cull
  of a whole batch, the early-out rounds, the runs of a pass.

:mod:`raplas_hdl.host.warm` compiles every kernel a render needs, once per machine (by
rendering a small scene through the host, so it lives there).

The host's backends (:mod:`raplas_hdl.host.backends`) drive it; nothing here imports
Amaranth or the host.
"""
