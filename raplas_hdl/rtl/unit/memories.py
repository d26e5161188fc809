"""The unit's memories: their geometry, the port signatures the stages use, the write decoder.

The eight memories themselves stay in the top (:class:`~raplas_hdl.rtl.intersection.
IntersectionUnit`), named as they always were (``tri_mem``, ``sph_mem``, ... : the job-stream
harness fills the scene memories through those instance names); each stage reads them
through a :func:`read_signature` port of its own, and the host's writes reach them through
the :class:`WriteDecoder`'s :func:`write_signature` ports. :func:`bind_read` and
:func:`bind_write` join such a port to a :class:`~raplas_hdl.rtl.ram.SyncRAM` port.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Module, Mux
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ...model.config import UnitConfig
from ...model.memory_image import REGIONS

__all__ = ["MEMORIES", "memory_geometry", "read_signature", "write_signature", "read_ports",
           "bind_read", "bind_write", "WriteDecoder"]

#: The memories: instance name in the unit, and the write decoder's port for it.
MEMORIES = {"tri": "tri_mem", "sphere": "sph_mem", "count": "cnt_mem", "tlist": "tlist_mem",
            "plane": "plane_mem", "ray": "ray_mem", "enable": "enable_mem",
            "rlist": "rlist_mem"}


def memory_geometry(cfg: UnitConfig) -> dict:
    """``{port: (word bits, depth, lane bits)}`` of every memory, in :data:`MEMORIES` order.

    Plane, Ray, enable and run-list memories hold two banks (bank 1 from ``depth / 2`` up).
    """
    w = cfg.fmt.width
    return {
        "tri": (12 * w, cfg.max_triangles, w),
        "sphere": (4 * w, cfg.max_spheres, w),
        "count": (cfg.count_bits, cfg.max_spheres, cfg.count_bits),
        "tlist": (cfg.tri_id_bits, cfg.max_spheres * cfg.tris_per_sphere, cfg.tri_id_bits),
        "plane": (4 * w, 2 * cfg.n_planes, w),
        "ray": (6 * w, 2 * cfg.n_rays, w),
        "enable": (1, 2 * cfg.n_rays, 1),
        "rlist": (cfg.sphere_id_bits, 2 * cfg.max_spheres, cfg.sphere_id_bits),
    }


def _abits(depth: int) -> int:
    # as SyncRAM: at least one address bit
    return max(1, (depth - 1).bit_length())


def read_signature(width: int, depth: int) -> wiring.Signature:
    """A synchronous read port as its reader sees it: ``addr`` and ``en`` out (``en`` high
    unless driven), ``data`` in, the word at ``addr`` of the last clock with ``en``."""
    return wiring.Signature({"addr": Out(_abits(depth)), "en": Out(1, init=1),
                             "data": In(width)})


def read_ports(cfg: UnitConfig, *names) -> dict:
    """The members ``{name: Out(read_signature(...))}`` of a stage that reads the memories
    ``names`` (keys of :data:`MEMORIES`)."""
    geometry = memory_geometry(cfg)
    return {name: Out(read_signature(*geometry[name][:2])) for name in names}


def write_signature(width: int, depth: int, lane: int) -> wiring.Signature:
    """A write port as its writer sees it: ``addr``, ``data``, ``en`` (one bit per lane)."""
    return wiring.Signature({"addr": Out(_abits(depth)), "data": Out(width),
                             "en": Out(width // lane)})


def bind_read(m: Module, ram_port, port) -> None:
    """Join a :class:`~raplas_hdl.rtl.ram.SyncRAM` read port to a :func:`read_signature`
    interface."""
    m.d.comb += [ram_port.addr.eq(port.addr), ram_port.en.eq(port.en),
                 port.data.eq(ram_port.data)]


def bind_write(m: Module, ram_port, port) -> None:
    """Join a :class:`~raplas_hdl.rtl.ram.SyncRAM` write port to a :func:`write_signature`
    interface."""
    m.d.comb += [ram_port.addr.eq(port.addr), ram_port.data.eq(port.data),
                 ram_port.en.eq(port.en)]


class WriteDecoder(wiring.Component):
    """The host write port decoded into one write port per memory (combinational).

    A 32-bit word ``wr_data`` at ``wr_addr`` (region, bank, index, field: the address map of
    :mod:`raplas_hdl.model.memory_image`) goes to the field's lane of the entry's word; an
    index beyond a memory's depth, or an unknown field, writes nothing.

    Parameters
    ----------
    config : UnitConfig

    Members
    -------
    wr_en, wr_addr, wr_data : In(1), In(32), In(32)
    tri, sphere, count, tlist, plane, ray, enable, rlist : Out(write_signature(...))
        The memories' write ports (:func:`memory_geometry`).
    plane_written : Out(2)
        Bit b: this cycle writes a plane of bank b.
    """

    def __init__(self, config: UnitConfig):
        self._cfg = config
        members = {"wr_en": In(1), "wr_addr": In(32), "wr_data": In(32)}
        for name, geometry in memory_geometry(config).items():
            members[name] = Out(write_signature(*geometry))
        members["plane_written"] = Out(2)
        super().__init__(members)

    def elaborate(self, platform):
        cfg = self._cfg
        w = cfg.fmt.width
        m = Module()
        region, bank = self.wr_addr[28:32], self.wr_addr[27]
        index, fld = self.wr_addr[4:27], self.wr_addr[0:4]
        word, wr = self.wr_data, self.wr_en

        def lanes(port, select, n):
            """A record memory: ``n`` lanes of ``W`` bits, field k -> lane k."""
            m.d.comb += port.data.eq(Cat(*[word[:w]] * n))
            for k in range(n):
                m.d.comb += port.en[k].eq(select & (fld == k))

        def banked(i, n):
            return Mux(bank, i + n, i)

        is_tri = wr & (region == REGIONS["tri"]) & (index < cfg.max_triangles) & (fld < 12)
        m.d.comb += self.tri.addr.eq(index)
        lanes(self.tri, is_tri, 12)
        is_sph = wr & (region == REGIONS["sphere"]) & (index < cfg.max_spheres)
        m.d.comb += [self.sphere.addr.eq(index),
                     self.count.addr.eq(index), self.count.data.eq(word),
                     self.count.en.eq(is_sph & (fld == 4))]
        lanes(self.sphere, is_sph, 4)
        m.d.comb += [self.tlist.addr.eq(index), self.tlist.data.eq(word),
                     self.tlist.en.eq(wr & (region == REGIONS["tlist"]) & (fld == 0)
                                      & (index < cfg.max_spheres * cfg.tris_per_sphere))]
        is_pl = wr & (region == REGIONS["plane"]) & (index < cfg.n_planes)
        m.d.comb += self.plane.addr.eq(banked(index, cfg.n_planes))
        lanes(self.plane, is_pl, 4)
        is_ray = wr & (region == REGIONS["ray"]) & (index < cfg.n_rays)
        m.d.comb += [self.ray.addr.eq(banked(index, cfg.n_rays)),
                     self.enable.addr.eq(banked(index, cfg.n_rays)),
                     self.enable.data.eq(word[0]), self.enable.en.eq(is_ray & (fld == 6))]
        lanes(self.ray, is_ray, 6)
        m.d.comb += [self.rlist.addr.eq(banked(index, cfg.max_spheres)),
                     self.rlist.data.eq(word),
                     self.rlist.en.eq(wr & (region == REGIONS["rlist"]) & (fld == 0)
                                      & (index < cfg.max_spheres))]
        m.d.comb += self.plane_written.eq(Mux(is_pl, Mux(bank, 0b10, 0b01), 0))
        return m
