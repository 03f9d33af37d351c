"""Benchmarks (``scripts/bench.py``): every figure a ratio measured side by side in one run.

- :mod:`evcd.bench.protocols`: fast vs paper episodes, overhead over the bare ``sumo`` binary, the
  day-snapshot build;
- :mod:`evcd.bench.equivalence`: the travel times of the two protocols on the same seeds;
- :mod:`evcd.bench.engines`: the batched engine against the single environment (equivalence,
  throughput, learning speed, two-process scaling, the results sweep's estimated wall time);
- :mod:`evcd.bench.replay`: the prioritized replay buffer's sample + priority update.
"""
