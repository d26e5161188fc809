"""Render helpers shared by the render tests (``host/test_conservative_render.py``,
``engine/test_certified_render.py``)."""

from raplas_hdl.host.backends import Backend, ModelBackend


class RawConservative(ModelBackend):
    """The conservative unit's hits folded as they come (the render before the re-check)."""

    def trace(self, *args, **kwargs):
        return Backend.trace(self, *args, **kwargs)

