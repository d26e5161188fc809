"""Tests of ``raplas_hdl.synth``."""
