"""Tests of ``raplas_hdl.host``."""
