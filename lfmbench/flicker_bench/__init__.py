"""Virtual IEEE P2020 flicker test bench (``lfmbench flicker-bench``, docs/guide/flicker-bench.md): flicker KPIs
of any sensor preset over PWM frequency, duty, LED luminance and every phase, exactly; sequences at a frame rate;
the preset's noise chain; real bench captures beside the simulation.

Modules, in data-flow order: :mod:`~lfmbench.flicker_bench.model` (a preset's capture plan and response for a flat
LED target), :mod:`~lfmbench.flicker_bench.exact` (every phase from the breakpoints of the piecewise-linear
exposure-vs-phase function), :mod:`~lfmbench.flicker_bench.sequence` (frames at a frame rate, frames to cover
every phase), :mod:`~lfmbench.flicker_bench.noise` (Monte Carlo through the preset's chain),
:mod:`~lfmbench.flicker_bench.realcap` (ROI-mean CSVs in the CARpublic P2020 layout) and
:mod:`~lfmbench.flicker_bench.run` (grid, tables, heat maps, report). Stage: above the baselines and the metrics it
runs (tests/test_layout.py).
"""
