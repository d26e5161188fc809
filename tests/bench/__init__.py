"""Tests of ``raplas_hdl.bench``."""
