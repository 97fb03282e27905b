"""rvstudy: the ``rv-stackup`` study (paper sections 4.2-5 and a Monte Carlo tolerance stack-up).

Modules: :mod:`rvstudy.study` (stages and configuration), :mod:`rvstudy.executor` (serial, local
process pool, Dask), :mod:`rvstudy.cache` (content-keyed, atomic case cache),
:mod:`rvstudy.montecarlo` (tolerances, yield, variance shares), :mod:`rvstudy.report` (Markdown
report and tables), :mod:`rvpaper` (the paper's published numbers, a leaf package), :mod:`rvstudy.cli`.
"""
