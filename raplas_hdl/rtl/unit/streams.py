"""The payloads of the streams between the unit's stages, derived from the model's records.

==================  ==========================  =========================================
stream              payload                     record
==================  ==========================  =========================================
cmd -> feeder       :func:`cmd_layout`          :data:`~raplas_hdl.model.records.CMD`
feeder -> array     :func:`sphere_layout`       ``SPHERE`` (``id`` is a :func:`tag_layout`)
array -> selector   :func:`mask_layout`         ``PS_RESULT`` (the same tag)
selector -> fetch   :func:`job_layout`          one ray of one sphere (this module)
fetch -> RT unit    :func:`pair_layout`         ``PAIR`` (``ray_id``'s top bit: marker)
RT unit -> framing  :func:`rt_result_layout`    ``RT_RESULT`` (the same marker bit)
framing -> o        :func:`result_layout`       ``RESULT``
==================  ==========================  =========================================

In ``certified`` mode the last two are ``RT_RESULT_CERTIFIED`` and ``RESULT_CERTIFIED``
(the pair's ``outcome`` on top; :func:`~raplas_hdl.model.records.result_record`).

A run's spheres are followed through every stage by one *marker* (a sphere, a job, a pair,
a result with the marker bit set) that the result framing turns into the run's ``last``
beat.
"""

from __future__ import annotations

from amaranth.lib import data

from ...model.config import UnitConfig
from ...model.records import (CMD, COUNTERS, PAIR, PS_RESULT, SPHERE, result_record,
                              rt_result_record)
from ..records import struct_layout

__all__ = ["tag_layout", "cmd_layout", "sphere_layout", "mask_layout", "job_layout",
           "pair_layout", "rt_result_layout", "result_layout", "counter_layout"]


def tag_layout(cfg: UnitConfig) -> data.StructLayout:
    """The sphere ID as the plane-sphere array carries it: the sphere, the marker bit, the
    run's bank and ``keep_all`` bit, from the low bits up."""
    return data.StructLayout({"sphere": cfg.sphere_id_bits, "marker": 1, "bank": 1,
                              "keep_all": 1})


def cmd_layout(cfg: UnitConfig) -> data.StructLayout:
    return struct_layout(CMD, cfg)


def sphere_layout(cfg: UnitConfig) -> data.StructLayout:
    return struct_layout(SPHERE, cfg.fmt, id_bits=tag_layout(cfg).size)


def mask_layout(cfg: UnitConfig) -> data.StructLayout:
    return struct_layout(PS_RESULT, cfg, id_bits=tag_layout(cfg).size)


def job_layout(cfg: UnitConfig) -> data.StructLayout:
    """One enabled ray of one sphere (or a run's marker): the job FIFO's word."""
    return data.StructLayout({"ray": cfg.ray_id_bits, "sid": cfg.sphere_id_bits, "bank": 1,
                              "ntris": cfg.count_bits, "marker": 1})


def pair_layout(cfg: UnitConfig, tag_bits: int = 1) -> data.StructLayout:
    """The ray-triangle unit's input; ``ray_id`` has ``tag_bits`` more on top: the marker
    (and, in a lane of :mod:`.lanes`, above it the job's last pair)."""
    return struct_layout(PAIR, cfg, ray_id_bits=cfg.ray_id_bits + tag_bits)


def rt_result_layout(cfg: UnitConfig, tag_bits: int = 1) -> data.StructLayout:
    return struct_layout(rt_result_record(cfg), cfg, ray_id_bits=cfg.ray_id_bits + tag_bits)


def result_layout(cfg: UnitConfig) -> data.StructLayout:
    return struct_layout(result_record(cfg), cfg)


def counter_layout(cfg: UnitConfig) -> data.StructLayout:
    return struct_layout(COUNTERS, cfg)
