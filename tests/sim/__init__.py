"""Tests of ``raplas_hdl.sim``."""
