"""Tests of ``raplas_hdl.model``."""
