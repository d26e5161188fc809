"""Tests of ``raplas_hdl.fp``."""
