"""The Hydra glue: only ``scripts/*.py`` (and their tests) import this package.

- :mod:`evcd.cli.params`: a composed config -> a dispatcher's arguments (the environments' come from
  :mod:`evcd.experiments`, which Python users outside the scripts read too);
- :mod:`evcd.cli.run_record`: the run's Hydra record; :mod:`evcd.cli.errors`: how a script ends a run
  on a bad setting.
"""
