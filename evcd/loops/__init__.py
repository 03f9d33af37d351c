"""The loops that drive episodes through a runner (:mod:`evcd.env.runners`): training and evaluation.

- :mod:`evcd.loops.train`: train a learner, then evaluate it beside a baseline on held-out episodes;
  :mod:`~evcd.loops.train_state` (checkpoints, resume), :mod:`~evcd.loops.train_log` (TensorBoard),
  :mod:`~evcd.loops.curves` (the run's learning curve);
- :mod:`evcd.loops.evaluate`: run a dispatcher on evaluation episodes; :mod:`~evcd.loops.hindsight`
  (the best station in hindsight, a bound played where an agent would be);
- :mod:`evcd.loops.seeds` (the run seed's streams), :mod:`evcd.loops.stats` (bootstrap intervals,
  paired differences), :mod:`evcd.loops.run_files` (what a run writes), :mod:`evcd.loops.progress`.
"""
