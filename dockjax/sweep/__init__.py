"""Hyper-parameter sweeps that never lose work (``dockjax sweep``, ``experiments/sweep.py``).

The package: :mod:`.config` (what a sweep is: its identity, chunks, reference definition,
validation), :mod:`.execute` (one chunk; local and Dask backends), :mod:`.resume` (the
folder checks and the resumable loop), :mod:`.report` (tables and figures).

A sweep runs one algorithm over a grid of population sizes × ρ × α_max × seeds on one
problem preset, scores every run against a reference front fixed before the first run
(conventions §8), and writes everything into one results folder::

    OUT/
      config.json            the sweep's identity (grid, seeds, iterations, chunk size, preset,
                             algorithm, reference definition) + informational versions
      reference.npz          front (r, 2), ideal, nadir, hv_ref: the fixed reference and
                             normalisation of every indicator in the folder
      chunks/chunk-00012.npz one file per finished chunk: a tidy table (one row per run) and
                             each run's final front (feasible non-dominated F, distinct)
      runs.csv               every run, sorted by (pop, rho, alpha_max, seed)
      summary.csv / .md      per setting: median and IQR of HV, medians of IGD, IGD+, GD,
                             SP, ONVG, sorted by median HV (best first)
      fronts.npz             every run's final front (F concatenated, offsets, run keys)
      heatmap_hv_pop150.png  median HV over ρ × α_max, one per population size (IMOCS)
      hv_vs_pop.png          HV against population size, one line per (ρ, α_max)
      fronts_best_worst.png  every seed's front of the best and the worst setting

Execution. Runs are grouped by population size and cut into chunks of at most ``chunk``
runs (balanced: ``ceil(n / ceil(n / chunk))`` runs each, so a population size has one
chunk shape). One chunk is one compiled, vmapped :func:`dockjax.algorithms.optimize` call
(per-run seeds and, for IMOCS, per-run ρ and α_max via ``batch_params``); a short chunk is
padded with repeats of its own runs, which are dropped. So there is one compilation per
population size (per process). Both cores: the CLI asks JAX for one CPU device per usable
core (``--devices``) and the chunk's runs are sharded over them (``shard_map``: each
device runs its share, no communication; bit-identical results): the kernel's cache-sized
passes are too small for XLA's intra-op threads, so one device per core is what keeps the
cores busy (docs/performance.md).

Never losing work. Each finished chunk is written atomically (temporary file in the same
folder, fsync, ``os.replace``), so a chunk file is either complete or absent, whatever
kills the process (Ctrl-C, ``kill -9``, power loss after the rename). Re-running the same
command resumes: ``config.json`` must match (else exit 2), ``reference.npz`` is reused,
chunk files that exist are loaded, not recomputed, and only the missing chunks run. The
assignment of runs to chunks is a function of the configuration alone (that is why the
chunk size is part of it: a run's numbers are reproduced bit for bit only in the same
compiled shape), so the final ``runs.csv`` of an interrupted and resumed sweep is identical
to an uninterrupted one's except for the ``wall_s`` column.

Reference front (conventions §8: in a sweep, scored one run at a time, the reference and the
normalisation are fixed before the first run and stored with the results). By default a
deterministic *pilot*: one chunk of runs of the same algorithm at its default
hyper-parameters (IMOCS: ρ = 0.4, α_max = 0.1), the largest population size and the
sweep's iterations, seeds 1_000_000, 1_000_001, ... (disjoint from the sweep's); the
reference front is the non-dominated union of their final feasible sets, and ideal / nadir
(the normalisation) are its per-objective minimum / maximum. It has the shape of a sweep
chunk, so it costs no extra compilation. ``--reference-front FILE`` (.npz or .csv, two
columns T, jerk) uses a stored best-known front instead. Because the pilot is no better
than a good run, runs can dominate parts of it (GD and IGD+ then approach 0 and HV can
exceed the pilot's own); the numbers are comparable within one folder, not across folders
with different references.

For MOCS, NSGA-II and MOPSO (which have no ρ or α_max) the grid is a single setting per
population size, and the rho and alpha_max columns hold nan.

``wall_s`` is the wall time of the run's chunk (compilation included for the first chunk of
a population size in a process) divided by the chunk's size.

Backends. ``local`` (default) runs chunks one after another in this process; it needs no
service. ``dask`` sends chunks to a Dask distributed cluster (``--scheduler ADDRESS``, or a
``LocalCluster`` of ``--workers`` workers started here); the client writes each chunk file
as its future completes, so the layout and the resume behaviour are the same. Dask rather
than Ray: Dask distributed is pip-installable pure Python (``pip install
'dockjax[distributed]'``), its ``LocalCluster`` starts in-process in about a second (tests
use it), it needs no daemon or head node, and a chunk is one plain function call — the
task-graph features where Ray's actor model would help are not needed here. The local
cluster uses threads by default (``--no-dask-processes``; XLA releases the GIL while it
runs and the workers share one compilation); ``--dask-processes`` starts worker processes
instead (each compiles once, using the persistent compilation cache).

Test hook: the environment variable ``DOCKJAX_SWEEP_PAUSE`` (seconds) makes the sweep
sleep after each chunk it writes, so that a test can kill it between chunks.
"""

from __future__ import annotations

from .config import COLUMNS, ChunkSpec, ConfigError, SweepConfig, load_front_file, make_config, pilot_spec, plan_chunks
from .execute import run_chunk
from .report import load_table, report
from .resume import prepare_folder, remove_created, run_sweep

__all__ = ["COLUMNS", "ConfigError", "ChunkSpec", "SweepConfig", "load_front_file", "make_config", "pilot_spec",
           "plan_chunks", "run_chunk", "load_table", "report", "prepare_folder", "remove_created", "run_sweep"]


