"""The pytest and host side of a DUT's simulation: the whole unit in a live session
(:mod:`.unit_harness`) or per cycle under cocotb (:mod:`.unit_driver`), the board top
(:mod:`.board_sim`) and the reducer alone (:mod:`.reducer_harness`); see
:mod:`raplas_hdl.sim` for why the whole unit has two drivers."""
