"""Verification campaigns: the seeded ray-triangle stress families
(:mod:`raplas_hdl.model.stress_cases`) judged by the exact reference (:mod:`.stress`) and the
sharded, resumable stress and culling campaign (:mod:`.campaign`). Nothing here imports
Amaranth."""
