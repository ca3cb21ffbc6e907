"""Studies that never lose work: hyper-parameter sweeps (``dockjax sweep``,
``experiments/sweep.py``) and the paper's comparison (``dockjax compare``, :mod:`.paper`).

A study names one or more algorithms and, per algorithm, values for any field of its
``Params`` (:mod:`.design`), runs every setting on common seeds — or races them, dropping
settings as soon as they are significantly worse than the best (:mod:`.race`) — scores
every run against a reference front fixed before the first run (:mod:`.reference`), and
reports which settings are as good as the best, and how sure that is (:mod:`.report`,
:mod:`dockjax.stats`). The paper's comparison is one such study, whose report adds the
paper's tables and figures (:mod:`.paper`). The package: :mod:`.config` (what a study is:
its identity, rounds and chunks), :mod:`.execute` (one chunk; local and Dask backends),
:mod:`.resume` (the folder checks and the resumable loop).

Files of a study folder::

    OUT/
      config.json        the study's identity (settings, seeds, chunk size, preset, race,
                         reference definition) + informational versions and command line
      reference.npz      front (r, 2), ideal, nadir, hv_ref, source: the fixed reference and
                         normalisation of every indicator in the folder (and, for the
                         best-known front, its trajectories X)
      chunks/round-000-chunk-00012.npz   one file per finished chunk: a tidy table (one row
                         per run), each run's final front (F and X) and its anytime hypervolume
      runs.csv           every run, sorted by (setting, seed)
      summary.csv / .md  per setting: median and bootstrap interval of HV and IGD+, tests
                         against the best, effect size, verdict
      report.md          the verdict, the table, the race's rounds, the figures
      fronts.npz, anytime_hv.png, eaf.png, heatmap_hv_*.png, hv_vs_pop.png, fronts_best_worst.png,
      importance_*.png (:mod:`.importance`)
      (compare adds paper.csv, table3.csv, table4.csv, chosen.json, fronts.png,
      left_arm_xyz.png, joints.png, convergence.png)
      over instances (:mod:`dockjax.instances`): references/instance-<k>.npz in place of
      reference.npz, hv_per_instance.png; with a test set (:mod:`.testset`): test/, a study
      of the best settings on the held-out instances, and hv_train_test.png; with the
      ablation path (:mod:`.ablation`): ablation/step-<k>/, one study a step, and ablation.png

Execution. A round's runs (setting, seed) are grouped by compiled program (algorithm,
population, iterations, static hyper-parameters) and cut into chunks of at most ``chunk``
runs; one chunk is one compiled, vmapped :func:`dockjax.optimize.optimize` call with every
run's own hyper-parameters (a ``Params`` pytree whose leaves carry a run axis); a short
chunk is padded with repeats of its own runs, which are dropped. The CLI asks JAX for one
CPU device per usable core and each chunk's runs are sharded over them.

Never losing work. Each finished chunk is written atomically (temporary file in the same
folder, fsync, ``os.replace``), so a chunk file is either complete or absent, whatever
kills the process. Re-running the same command resumes: ``config.json`` must match (else
exit 2), ``reference.npz`` is reused, chunk files that exist are loaded, not recomputed,
and only the missing chunks run; a race takes the same decisions again from the stored
scores. The assignment of runs to chunks is a function of the configuration and of those
scores alone (a run's numbers are reproduced bit for bit only in the same compiled shape,
which is why the chunk size is part of the configuration), so the final ``runs.csv`` of an
interrupted and resumed study equals an uninterrupted one's except for the ``wall_s``
column.

Backends. ``local`` (default) runs chunks one after another in this process. ``dask``
sends a round's chunks to a Dask distributed cluster (``--scheduler ADDRESS``, or a
``LocalCluster`` of ``--workers`` workers started here); the client writes each chunk file
as its future completes, so the layout and the resume behaviour are the same. Dask rather
than Ray: it is pip-installable pure Python, its ``LocalCluster`` starts in-process in
about a second (the tests use it), it needs no daemon, and a chunk is one plain function
call.

Test hook: the environment variable ``DOCKJAX_SWEEP_SIGNAL=NAME:N`` (e.g. ``SIGKILL:3``)
makes the sweep send itself that signal right after writing its N-th chunk, so that a test
can kill or interrupt it at a known point.
"""

from __future__ import annotations

from .config import COLUMNS, ChunkSpec, ConfigError, SweepConfig, load_front_file, make_config, pilot_spec, plan_round
from .design import ParamSpec, Setting, build_settings, parse_param
from .execute import run_chunk
from .paper import paper_config, paper_tables
from .report import Study, load_config, load_study, load_table, report, summarise
from .resume import Claim, claim_folder, prepare_folder, remove_created, run_sweep

__all__ = ["COLUMNS", "ChunkSpec", "ConfigError", "SweepConfig", "load_front_file", "make_config", "pilot_spec",
           "plan_round", "ParamSpec", "Setting", "build_settings", "parse_param", "run_chunk", "paper_config",
           "paper_tables", "Study", "load_config", "load_study", "load_table", "report", "summarise",
           "Claim", "claim_folder", "prepare_folder", "remove_created", "run_sweep"]
