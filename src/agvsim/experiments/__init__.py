"""Batch experiments above the simulator: parameter sweeps (``agvsim sweep``) on local processes
or on Ray, and the grading of students' controllers (``agvsim grade``, in ``agvsim.grade``).

* :mod:`agvsim.experiments.paths`: dotted paths into a scenario (``robots.0.params.wheel_radius_m``)
* :mod:`agvsim.experiments.spec`: the sweep file, its variations, their validation
* :mod:`agvsim.experiments.runs`: one headless run -> its summary (no files)
* :mod:`agvsim.experiments.executors`: local processes and Ray
* :mod:`agvsim.experiments.table`: rows -> Parquet / CSV table, comparison plots
* :mod:`agvsim.experiments.sweep`: ``run_sweep``: validate, skip finished runs, run, assemble
"""

from agvsim.experiments.spec import SweepError, SweepPlan, load_sweep, plan_sweep
from agvsim.experiments.sweep import SweepResult, run_sweep

__all__ = ["SweepError", "SweepPlan", "SweepResult", "load_sweep", "plan_sweep", "run_sweep"]
