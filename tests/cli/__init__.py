"""Tests of ``raplas_hdl.cli``."""
