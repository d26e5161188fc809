"""Tests of ``raplas_hdl.verify``."""
