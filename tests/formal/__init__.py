"""Tests of ``raplas_hdl.formal``."""
