"""rvstudy: the ``rv-stackup`` study (paper sections 4.2-5 and a Monte Carlo tolerance stack-up).

Modules: :mod:`rvstudy.study` (stages and configuration), :mod:`rvstudy.screen` (single-factor
screen and factor sweeps), :mod:`rvstudy.montecarlo` (tolerances, yield, variance shares),
:mod:`rvstudy.report` (Markdown report and tables), :mod:`rvstudy.cli`. Cases are solved by
:mod:`rvdyn.runner` (cache and executors); the paper's published numbers are :mod:`rvpaper`.
"""
