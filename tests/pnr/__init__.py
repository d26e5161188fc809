"""Tests of ``raplas_hdl.pnr``."""
