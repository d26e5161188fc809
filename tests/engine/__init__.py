"""Tests of ``raplas_hdl.engine``."""
