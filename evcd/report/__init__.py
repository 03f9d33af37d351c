"""From finished runs to what a reader sees: tables and figures.

- :mod:`evcd.report.sweep`: read a Hydra multirun (which jobs finished, which are missing or failed);
- :mod:`evcd.report.seed_stats`: intervals across seeds, the share of the greedy -> hindsight gap;
- :mod:`evcd.report.table`: the results table (CSV, Markdown, figures);
- :mod:`evcd.report.figures`: the figures (bars, learning curves over seeds, a scenario's day);
- :mod:`evcd.report.scenario`: the tables of a simulated day (``scripts/inspect_scenario.py``).
"""
