"""Stages 1 and 2: the command / plane loader and the sphere feeder.

Run position -> [run-list read] -> [the sphere's index on a register] -> [Sphere Memory
read] -> [the sphere on a register] -> sphere FIFO -> ``o``, a 4-stage pipeline that never
stalls, one sphere per cycle, then the run's marker (the registers keep each block RAM's
clock-to-out off the wires to the next memory and to the array, as in :mod:`.fetch`); before
a run whose bank's planes are not the array's, the drain and the plane load (see
``docs/intersection-unit.md``).

Flow control is by credits, as in the record fetch: the feeder starts a sphere only while it
holds a credit, one per entry of its sphere FIFO (:data:`SPHERE_FIFO_DEPTH`), given back a
cycle after the FIFO gives the sphere to the array. As a stall pipeline its enable, fanned out
from the array's ``ready`` to some 200 registers and the block RAMs' enables, was the whole
unit's critical path after place and route (10.3 ns at speed 6, 9.3 ns of it routing).
"""

from __future__ import annotations

from amaranth.hdl import Module, Mux, Signal
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from ...model.config import UnitConfig
from ...model.records import PLANE
from ..records import struct_layout
from .credit_fifo import CreditFIFO
from .memories import read_ports
from .streams import cmd_layout, sphere_layout, tag_layout

__all__ = ["SphereFeeder", "SPHERE_FIFO_DEPTH"]

#: Entries of the sphere FIFO (the feeder's credits): the pipeline's four stages, the FIFO's
#: two-cycle write-to-read and the credit's two-cycle way back, so that one sphere per cycle
#: never waits for a credit while the array takes one per cycle.
SPHERE_FIFO_DEPTH = 8


class SphereFeeder(wiring.Component):
    """Accepts runs on ``cmd``; loads the run's planes into the array when they are stale;
    sends the run's spheres, then its marker, on ``o``.

    Parameters
    ----------
    config : UnitConfig
    capacity : int
        More than the spheres the array can hold between its ``i`` and ``o`` handshakes.
        The feeder counts the spheres between its own FIFO's input and the array's output,
        so up to ``capacity + SPHERE_FIFO_DEPTH``.

    Members
    -------
    cmd : In(stream.Signature(cmd_layout))
        Runs; ``ready`` while the feeder is idle.
    o : Out(stream.Signature(sphere_layout))
        Spheres for the array, from the sphere FIFO; ``id`` is a
        :func:`~.streams.tag_layout`.
    pw_en, pw_addr, pw_data : Out(1), Out(range(rows + cols)), Out(PLANE layout)
        The array's plane write port.
    rlist, sphere, plane : Out(read_signature(...))
        Run-list, Sphere Memory and Plane Memory read ports.
    plane_written : In(2)
        Bit b: the host writes a plane of bank b this cycle (the bank goes stale).
    retired : In(1)
        The selector took a sphere (out of the sphere slice behind the array); taken a cycle
        late.
    spheres : Out(1)
        A sphere of a run (not a marker) enters the sphere FIFO this cycle (on its way to
        the array: counted once per sphere, as the array tests it).
    """

    def __init__(self, config: UnitConfig, capacity: int):
        self._cfg = config
        self._capacity = capacity
        super().__init__({
            **read_ports(config, "rlist", "sphere", "plane"),
            "cmd": In(stream.Signature(cmd_layout(config))),
            "o": Out(stream.Signature(sphere_layout(config))),
            "pw_en": Out(1), "pw_addr": Out(range(config.n_planes)),
            "pw_data": Out(struct_layout(PLANE, config)),
            "plane_written": In(2), "retired": In(1), "spheres": Out(1),
        })

    def elaborate(self, platform):
        cfg = self._cfg
        m = Module()
        n_planes, sid_bits, w = cfg.n_planes, cfg.sphere_id_bits, cfg.fmt.width
        tag = tag_layout(cfg)
        run = Signal(cmd_layout(cfg))         # the run being fed
        pos = Signal(cfg.run_count_bits)      # its next position
        f1 = Signal(data.StructLayout({"v": 1, "ind": 1, "sid": sid_bits, "tag": tag}))
        fs = Signal(data.StructLayout({"v": 1, "tag": tag}))
        f2 = Signal(data.StructLayout({"v": 1, "tag": tag}))
        f3 = Signal(data.StructLayout({"v": 1, "tag": tag, "c": 3 * w, "r": w}))
        m.submodules.fifo = fifo = CreditFIFO(width=self.o.payload.shape().size,
                                              depth=SPHERE_FIFO_DEPTH)
        # credits: free sphere FIFO entries not yet claimed by a started sphere
        credit = Signal(range(SPHERE_FIFO_DEPTH + 1), init=SPHERE_FIFO_DEPTH)
        freed = Signal()
        go = Signal()                         # a sphere (or the marker) may start
        issue = Signal()
        issue_marker = Signal()
        m.d.comb += go.eq(credit != 0)
        m.d.sync += [freed.eq(fifo.r_stream.valid & fifo.r_stream.ready),
                     credit.eq(credit - issue + freed)]

        # a plane write makes that bank's planes stale in the array
        dirty = Signal(2, init=0b11)
        new_dirty = Signal(2)
        loaded_bank = Signal()
        m.d.comb += new_dirty.eq(dirty | self.plane_written)
        m.d.sync += dirty.eq(new_dirty)
        # spheres between the array's input and output handshakes: the planes may change
        # only when none is left
        in_array = Signal(range(self._capacity + SPHERE_FIFO_DEPTH))
        # (``retired`` comes from the selector's take out of the sphere slice: registered
        # here, so that the chain selector -> array -> this counter is cut; the count then
        # lags by a cycle, which only delays a drain by one)
        retired = Signal()
        m.d.sync += [retired.eq(self.retired), in_array.eq(in_array + f3.v - retired)]
        drained = Signal()
        m.d.comb += drained.eq((in_array == 0) & ~f1.v & ~fs.v & ~f2.v & ~f3.v)

        ld_k = Signal(range(n_planes))
        ld_v = Signal()
        ld_kd = Signal(range(n_planes))
        m.d.sync += [ld_v.eq(0), ld_kd.eq(ld_k)]
        with m.FSM(name="feeder"):
            with m.State("START"):
                # one state change after reset, so that every simulator evaluates the
                # processes that depend on the state (Icarus does not run them at time 0)
                m.next = "IDLE"
            with m.State("IDLE"):
                m.d.comb += self.cmd.ready.eq(1)
                with m.If(self.cmd.valid):
                    p = self.cmd.payload
                    m.d.sync += [run.eq(p), pos.eq(0)]
                    stale = (p.bank != loaded_bank) | new_dirty.bit_select(p.bank, 1)
                    with m.If(stale):
                        m.next = "DRAIN"
                    with m.Else():
                        m.next = "FEED"
            with m.State("DRAIN"):
                with m.If(drained):
                    m.d.sync += [ld_k.eq(0), loaded_bank.eq(run.bank)]
                    m.next = "LOAD"
            with m.State("LOAD"):
                m.d.comb += self.plane.addr.eq(Mux(run.bank, ld_k + n_planes, ld_k))
                m.d.sync += [ld_k.eq(ld_k + 1), ld_v.eq(1)]
                with m.If(ld_k == 0):
                    # the bank is clean from the first read on (a write after it re-dirties)
                    m.d.sync += dirty.eq(new_dirty & Mux(run.bank, 0b01, 0b10))
                with m.If(ld_k == n_planes - 1):
                    m.next = "FEED"
            with m.State("FEED"):
                m.d.comb += [issue.eq(go), issue_marker.eq(pos == run.count)]
                with m.If(go):
                    m.d.sync += pos.eq(pos + 1)
                    with m.If(issue_marker):
                        m.next = "IDLE"
        m.d.comb += [self.pw_en.eq(ld_v), self.pw_addr.eq(ld_kd),
                     self.pw_data.eq(self.plane.data)]

        # position -> f1 (run-list read) -> fs (the index) -> f2 (Sphere Memory read) -> f3
        sid_direct = Signal(sid_bits)
        m.d.comb += [sid_direct.eq(run.first + pos),
                     self.rlist.addr.eq(Mux(run.bank, sid_direct + cfg.max_spheres,
                                            sid_direct)),
                     self.rlist.en.eq(1)]
        f1_sid = Signal(sid_bits)
        m.d.comb += [f1_sid.eq(Mux(f1.ind, self.rlist.data, f1.sid)),
                     self.sphere.addr.eq(fs.tag.sphere), self.sphere.en.eq(1)]
        m.d.sync += [f1.v.eq(issue), f1.ind.eq(run.indirect), f1.sid.eq(sid_direct),
                     f1.tag.marker.eq(issue_marker), f1.tag.bank.eq(run.bank),
                     f1.tag.keep_all.eq(run.keep_all),
                     fs.v.eq(f1.v), fs.tag.eq(f1.tag), fs.tag.sphere.eq(f1_sid),
                     f2.v.eq(fs.v), f2.tag.eq(fs.tag),
                     f3.v.eq(f2.v), f3.tag.eq(f2.tag), f3.c.eq(self.sphere.data[:3 * w]),
                     f3.r.eq(self.sphere.data[3 * w:4 * w])]
        # the credits leave the FIFO room for every started sphere: the FIFO takes every
        # write (:mod:`.credit_fifo`)
        fifo_in = data.View(self.o.payload.shape(), fifo.w_stream.payload)
        m.d.comb += [fifo.w_stream.valid.eq(f3.v), fifo_in.id.eq(f3.tag),
                     fifo_in.c.eq(f3.c), fifo_in.r.eq(f3.r),
                     self.spheres.eq(f3.v & ~f3.tag.marker)]
        wiring.connect(m, fifo.r_stream, wiring.flipped(self.o))
        return m
