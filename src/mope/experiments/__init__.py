"""Experiments: run folders (``runs.py``), the one executor for batches of jobs (``jobs.py``) and the kinds
of job it runs (``job_kinds.py``), sweeps, reports and their statistics, folder locks and plotting.

``from mope.experiments import train_run`` keeps working: the names of the former module ``mope.experiments`` (now
:mod:`mope.experiments.runs`) are served from there on first use (:func:`mope.moved.former_module_names`).
"""

from mope.moved import former_module_names

__getattr__ = former_module_names(__name__, "mope.experiments.runs")
