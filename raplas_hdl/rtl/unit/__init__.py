"""The stages of the intersection unit, each a ``wiring.Component`` joined to the next by a
stream (:mod:`.streams`); :class:`raplas_hdl.rtl.intersection.IntersectionUnit` wires them,
with the plane-sphere array, the ray-triangle unit, the FIFOs and the memories.

- :mod:`.memories`: memory geometry, read and write port signatures, :class:`WriteDecoder`;
- :mod:`.feeder`: :class:`SphereFeeder` (command / plane loader, sphere feeder);
- :mod:`.selector`: :class:`PairSelector` (ray iterator, enable lookup);
- :mod:`.fetch`: :class:`RecordFetch` (triangle expander, record fetch);
- :mod:`.framing`: :class:`ResultFraming`, :class:`EventCounters`.

Their docs, streams and the stall and drain rules: ``docs/intersection-unit.md``.
"""
