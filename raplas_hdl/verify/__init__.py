"""Verification campaigns: the seeded ray-triangle stress families (:mod:`.stress`) and the
sharded, resumable stress and culling campaign (:mod:`.campaign`). Nothing here imports
Amaranth."""
