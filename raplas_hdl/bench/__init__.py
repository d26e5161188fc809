"""``raplas-hdl bench``: run time against error, with hardware cost and the Pareto front.

- :mod:`.plan`: the sweep's points (format x rounding x mode x scene x bundle x backend);
- :mod:`.instrumented`: the model backend of the sweep (runs counted, budgeted, sampled);
- :mod:`.metrics`: what is measured at a point (render timings and throughput, the device's
  cycles and result-link bits from the unit's counters, error against float64 per pair and
  per pixel, error against the exact reference R from the stress families);
- :mod:`.sweep`: each point rendered under a cap on the pairs it may issue, and measured;
- :mod:`.cost`: the hardware cost of each format and rounding from Yosys (through
  :mod:`raplas_hdl.synth`, cached), the synthesis checks of the FP24 units, and the device
  model (the synthesised intersection unit's resources per format, units per XC4VSX35,
  cycles of a frame);
- :mod:`.pareto`: configurations aggregated over scenes, and their Pareto fronts;
- :mod:`.report`: CSV, JSON, PNG plots and the markdown report.

Nothing here imports Amaranth at module level (only :mod:`raplas_hdl.synth` elaborates
units, when a synthesis is not cached).
"""

from .pareto import aggregate, pareto_front
from .plan import BenchSpec, full_spec, quick_spec
from .sweep import run_sweep

__all__ = ["BenchSpec", "aggregate", "full_spec", "pareto_front", "quick_spec", "run_sweep"]
