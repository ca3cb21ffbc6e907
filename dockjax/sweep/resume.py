"""Never losing work: the results folder is checked before anything runs, every finished
chunk is written atomically, and a re-run computes only the chunks that are missing."""

from __future__ import annotations

import json
import os
import shutil
import signal
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable

import jax
import numpy as np
from tqdm import tqdm

from ..io import atomic_savez, atomic_write_text
from ..version import __version__
from .config import ChunkSpec, ConfigError, SweepConfig, plan_round, round_seeds
from .design import Setting
from .execute import DaskBackend, LocalBackend, run_chunk
from .files import DamagedFileError, load_npz
from .race import eliminate
from .reference import fixed_reference

__all__ = ["prepare_folder", "remove_created", "run_sweep", "scores_table"]


def _diff(a: dict, b: dict) -> list[str]:
    keys = sorted(set(a) | set(b))
    out = []
    for k in keys:
        x, y = a.get(k), b.get(k)
        if x == y:
            continue
        if k == "settings" and isinstance(x, list) and isinstance(y, list):
            label = lambda d: Setting.from_identity(d).label  # noqa: E731
            only_x = [label(d) for d in x if d not in y][:2]
            only_y = [label(d) for d in y if d not in x][:2]
            out.append(f"settings: folder has {len(x)} (e.g. {only_x or 'the same ones in another order'}), "
                       f"command gives {len(y)} (e.g. {only_y or 'the same ones in another order'})")
        elif k == "devices":
            def what(n):
                return f"{n} CPU device(s)" if n is not None else "Dask workers (--backend dask)"
            out.append(f"devices: the folder's runs were made on {what(x)}, this command runs them on {what(y)} "
                       "(the numbers depend on it)")
        else:
            out.append(f"{k}: folder has {x!r}, command gives {y!r}")
    return out


def prepare_folder(out: Path, cfg: SweepConfig) -> list[Path]:
    """Check that ``out`` can hold this sweep: created if missing (returns the folders
    created, outermost first, so that a caller can remove them), writable, and either new,
    empty or holding the same configuration with chunk files of this plan. Raises
    ConfigError; on error, folders created here are removed."""
    out = Path(out)
    created: list[Path] = []
    try:
        if out.exists() and not out.is_dir():
            raise ConfigError(f"--out {out} exists and is not a folder")
        if out.exists():
            cfg_path = out / "config.json"
            if cfg_path.exists():
                try:
                    stored = json.loads(cfg_path.read_text())["identity"]
                except (OSError, ValueError, KeyError, TypeError) as exc:
                    raise ConfigError(f"--out {out}: config.json is unreadable ({exc}); use another folder") from None
                want = json.loads(json.dumps(cfg.identity()))
                if stored != want:
                    raise ConfigError(f"--out {out} holds a different sweep configuration ("
                                      + "; ".join(_diff(stored, want)) + "); use another folder or the same options")
            elif any(not p.name.startswith(".") for p in out.iterdir()):
                raise ConfigError(f"--out {out} is not empty and holds no sweep (no config.json); "
                                  "use a new or empty folder")
        else:
            missing = []
            p = out
            while not p.exists():
                missing.append(p)
                p = p.parent
            for p in reversed(missing):
                try:
                    p.mkdir()
                except OSError as exc:
                    raise ConfigError(f"--out {out} cannot be created: {exc.strerror or exc}") from None
                created.append(p)
        try:
            fd, probe = tempfile.mkstemp(dir=out, prefix=".write-test.")
            os.close(fd)
            os.unlink(probe)
        except OSError as exc:
            raise ConfigError(f"--out {out} cannot be written: {exc.strerror or exc}") from None
    except ConfigError:
        remove_created(created)
        raise
    return created


def remove_created(created: list[Path]) -> None:
    """Remove folders this invocation created (outermost first in ``created``)."""
    if created:
        shutil.rmtree(created[0], ignore_errors=True)


def _write_config(out: Path, cfg: SweepConfig) -> None:
    path = out / "config.json"
    if path.exists():
        return
    doc = {"identity": cfg.identity(),
           "info": {"dockjax": __version__, "jax": jax.__version__, "numpy": np.__version__,
                    "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "argv": sys.argv}}
    atomic_write_text(path, json.dumps(doc, indent=2) + "\n")


def scores_table(out: Path, cfg: SweepConfig, column: str = "HV") -> np.ndarray:
    """(settings, seeds) of one indicator over every chunk file in ``out/chunks`` (NaN where
    a run has not happened)."""
    table = np.full((len(cfg.settings), cfg.seeds), np.nan)
    for path in sorted((out / "chunks").glob("round-*-chunk-*.npz")):
        z = load_npz(path)
        table[z["setting"], z["seed"]] = z[column]
    return table


def _check(path: Path, spec: ChunkSpec) -> bool:
    """Whether a chunk file is complete and holds the runs of ``spec`` (ConfigError if it
    holds other runs: the folder belongs to another plan)."""
    if not path.exists():
        return False
    try:
        z = load_npz(path)
        settings, seeds, _ = z["setting"], z["seed"], z["front_offsets"]
    except (DamagedFileError, KeyError):  # truncated, damaged or incomplete: recomputed
        return False
    if tuple(settings.tolist()) != spec.settings[:spec.n_real] or tuple(seeds.tolist()) != spec.seeds[:spec.n_real]:
        raise ConfigError(f"--out {path.parent.parent}: {path.name} holds other runs than this sweep's plan; "
                          "use another folder")
    return True


def _signal_hook() -> tuple[int, int] | None:
    """The test hook ``DOCKJAX_SWEEP_SIGNAL=NAME:N`` (e.g. ``SIGKILL:3``): the sweep sends
    itself that signal right after writing its N-th chunk, as a user's ``kill -9`` or Ctrl-C
    at that moment would. → (signal number, N) or None."""
    spec = os.environ.get("DOCKJAX_SWEEP_SIGNAL", "")
    if not spec:
        return None
    name, _, count = spec.partition(":")
    return int(getattr(signal, name)), int(count or 1)


def run_sweep(cfg: SweepConfig, out: Path, *, front: np.ndarray | None = None, backend: str = "local",
              scheduler: str | None = None, workers: int = 2, dask_processes: bool = False,
              progress: bool = True, log: Callable[[str], None] = print) -> int:
    """Run every missing chunk of the sweep in ``out`` (after :func:`prepare_folder`), round
    after round (one round without racing). Returns the number of chunks computed now."""
    out = Path(out)
    chunks_dir = out / "chunks"
    if backend == "dask":
        try:
            be = DaskBackend(scheduler, workers, dask_processes)
        except (OSError, TimeoutError) as exc:
            where = f"the Dask scheduler at {scheduler}" if scheduler else "a Dask LocalCluster"
            raise ConfigError(f"cannot connect to {where}: {exc}") from None
    else:
        be = LocalBackend()
    hook = _signal_hook()
    computed = 0
    try:
        _write_config(out, cfg)
        chunks_dir.mkdir(exist_ok=True)
        for folder in (out, chunks_dir):  # temporary files left by a kill during a write
            for stale in folder.glob(".*.*.tmp"):
                stale.unlink(missing_ok=True)
        kind = f"race over {cfg.seeds} seeds (min {cfg.race['min_seeds']})" if cfg.race else f"{cfg.seeds} seeds"
        log(f"sweep: {', '.join(cfg.algorithms)}; {len(cfg.settings)} settings, {kind}, {cfg.n_runs()} runs at most")
        ref = fixed_reference(out, cfg, front, be, log)
        reference = {k: ref[k] for k in ("front", "ideal", "nadir", "hv_ref")}
        alive = np.ones(len(cfg.settings), bool)
        seeds_done, r = 0, 0
        bar = tqdm(total=None if cfg.race else cfg.n_runs(), unit="run", disable=not progress, file=sys.stderr,
                   dynamic_ncols=True, smoothing=0.1)
        times: dict[tuple, list[float]] = {}
        try:
            while True:
                seeds = round_seeds(cfg, r, seeds_done, int(alive.sum()))
                if len(seeds) == 0:
                    break
                plan = plan_round(cfg, r, alive, seeds)
                done = [c for c in plan if _check(chunks_dir / c.name, c)]
                todo = [c for c in plan if c not in done]
                if done:
                    log(f"round {r}: resuming, {len(done)} of {len(plan)} chunks already done")
                bar.update(sum(c.n_real for c in done))

                def say(message: str) -> None:  # a line of its own, not glued to the progress bar
                    bar.clear()
                    log(message)
                    bar.refresh()

                for spec, res in be.map(run_chunk, todo, reference):
                    atomic_savez(chunks_dir / spec.name, res)
                    computed += 1
                    seconds = float(res["wall_s"][0]) * len(spec.seeds)
                    key = (spec.label, spec.pop, spec.iters)
                    times.setdefault(key, []).append(seconds)
                    bar.update(spec.n_real)
                    t = times[key]
                    bar.set_postfix_str(f"{spec.algorithm} pop {spec.pop}: " + (
                        f"first chunk (compile + run) {seconds:.1f} s" if len(t) == 1 else
                        f"{np.median(t[1:]):.2f} s/chunk"))
                    if hook and computed == hook[1]:
                        os.kill(os.getpid(), hook[0])
                seeds_done = seeds.stop
                if cfg.race is None:
                    break
                before = int(alive.sum())
                alive = eliminate(scores_table(out, cfg), alive, cfg.race["alpha"], cfg.race["min_seeds"])
                say(f"round {r}: seeds {seeds.start}..{seeds.stop - 1}, {before} settings raced, "
                    f"{int(alive.sum())} left")
                r += 1
                if alive.sum() <= 1 or seeds_done >= cfg.seeds:
                    break
        finally:
            bar.close()
        for (algorithm, pop, iters), t in times.items():
            rest = np.median(t[1:]) if len(t) > 1 else 0.0
            later = f", later chunks {rest:.2f} s each (compile ≈ {max(t[0] - rest, 0):.1f} s)" if len(t) > 1 else ""
            log(f"{algorithm} pop {pop}, {iters} iterations: first chunk {t[0]:.1f} s{later}")
        return computed
    finally:
        be.close()
