"""Tests of ``raplas_hdl.rtl.unit``."""
