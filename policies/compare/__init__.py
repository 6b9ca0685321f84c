"""``remarl-fc compare``: the paper's comparisons as one repeatable grid.

A grid is scenarios × methods × seeds (`policies.compare.grid`). Each cell trains its method on
its budget (E2Coop is a planner: nothing to train), evaluates the result with the one
evaluation code of the project (`sim.evaluation`), and writes
``runs/SCENARIO/METHOD/seedK/{curve.csv, result.json}`` (`policies.compare.methods`). A cell
with a ``result.json`` is finished: a rerun skips it (resume). Cells run in a local process
pool, or on a Ray cluster with ``ray_address`` (`policies.compare.cluster`).
`write_reports` (`policies.compare.report`) then draws ``learning_curves.png`` (one panel per
scenario, mean ± std over seeds of the per-episode Swarming return, as the paper's Fig. 3) and
writes ``summary.md``, ``table2.md`` and ``table2.csv`` (reaction time, energy, min d_U2O and
min d_U2U of reMARL against E2Coop in each scenario of the grid, the paper's numbers beside
ours where the paper has them: 3u2o).

Methods: ``remarl`` (per-agent DDPG with the full reMARL reward), ``coma`` (policies/coma.py),
``mappo``, ``iql``, ``vdn``, ``qmix`` (BenchMARL, the ``baselines`` extra) and ``e2coop``
(policies/e2coop.py). The MARL baselines train on the Swarming reward only, with a discrete
heading set (`n_actions`, said in every output).
"""

from policies.compare.grid import (
    BENCHMARL_METHODS,
    EXIT_STOPPED,
    METHODS,
    PARENT_POLL_S,
    CellReport,
    CompareConfig,
    Job,
    cell_line,
    jobs,
    run_grid,
    worker_setup,
)
from policies.compare.methods import reaction_ms, run_job
from policies.compare.report import PAPER_TABLE2, PAPER_TABLE2_SCENARIO, write_reports

__all__ = [
    "BENCHMARL_METHODS",
    "EXIT_STOPPED",
    "METHODS",
    "PAPER_TABLE2",
    "PAPER_TABLE2_SCENARIO",
    "PARENT_POLL_S",
    "CellReport",
    "CompareConfig",
    "Job",
    "cell_line",
    "jobs",
    "reaction_ms",
    "run_grid",
    "run_job",
    "worker_setup",
    "write_reports",
]
