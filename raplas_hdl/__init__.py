"""raplas-hdl: the RAPLAS ray-tracing intersection accelerator in Amaranth HDL, its
bit-exact golden model, co-simulation, and a host that renders through either."""

__version__ = "0.1.0"
