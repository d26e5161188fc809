"""Render helpers shared by the render tests (``host/test_conservative_render.py``,
``engine/test_certified_render.py``)."""

from raplas_hdl.host.modes import PaperMode, register_mode


class RawConservative(PaperMode):
    """The conservative unit's hits folded as they come (the render before the re-check): a
    render mode registered from the tests alone (``mode=RAW_CONSERVATIVE``)."""

    name = "test-raw-conservative"
    unit_mode = "conservative"


#: The name the backends know :class:`RawConservative` by.
RAW_CONSERVATIVE = register_mode(RawConservative()).name
