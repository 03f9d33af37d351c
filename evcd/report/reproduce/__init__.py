"""Every published page from one command (``scripts/reproduce.py``): a page's jobs as data, run as Hydra
multiruns of the scripts, rendered, and compared with the data the page commits.

- :mod:`~evcd.report.reproduce.spec`: a page's definition (``docs/reproduce/<page>.yaml``: its sweeps, what
  is rendered from them and the committed files it is compared with), its jobs and their commands;
- :mod:`~evcd.report.reproduce.found`: the jobs of a page found in run directories (missing, failed,
  of another task or experiment), and the command that completes them;
- :mod:`~evcd.report.reproduce.launch`: running a page's sweeps into an output folder (resumable),
  timed, and the launcher plugins they need;
- :mod:`~evcd.report.reproduce.render`: the page's tables from the jobs, their wall times and stamp;
- :mod:`~evcd.report.reproduce.check`: where a rendering differs from the committed data, cell by cell;
- :mod:`~evcd.report.reproduce.cost`: what a page's command costs, measured on its small version
  (``bench.py --suite reproduce``).
"""
