"""Data shipped with the package: test meshes (``meshes/``, licence notes in its README)."""
