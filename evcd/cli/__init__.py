"""The Hydra glue: only ``scripts/*.py`` (and their tests) import this package.

- :mod:`evcd.cli.params`: a composed config -> the library's arguments (environment, demand, agent);
- :mod:`evcd.cli.schema`: the structured configs (settings declared once, in dataclasses);
- :mod:`evcd.cli.errors`: how a script ends a run on a bad setting.
"""
