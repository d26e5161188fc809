"""The host link to the board: the driver that speaks the board's register map
(:mod:`raplas_hdl.model.board_map`) over any bus object (:mod:`.driver`). Nothing here
imports Amaranth or cocotb."""
