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
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import jax
import numpy as np
from tqdm import tqdm

from ..io import TEMP_PREFIX, FolderBusyError, FolderLock, atomic_write_text, make_folders
from ..version import __version__
from .config import ConfigError, SweepConfig, blocks_of, plan_round, round_seeds
from .design import Setting
from .execute import DaskBackend, LocalBackend, run_chunk
from .files import read_chunk, write_chunk
from .race import decide
from .reference import fixed_references

__all__ = ["Claim", "claim_folder", "prepare_folder", "remove_created", "run_sweep"]


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
        elif k in ("instances", "test_instances"):
            def names(v):
                v = v or []
                shown = ", ".join(d["name"] for d in v[:3]) + (", ..." if len(v) > 3 else "")
                return f"{len(v)} ({shown})" if v else "none (the preset's move)"
            same = [d["name"] for d in x or []] == [d["name"] for d in y or []]
            out.append(f"{k}: folder has {names(x)}, command gives {names(y)}"
                       + (" with other moves or limits" if same else ""))
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
                    if not isinstance(stored, dict):
                        raise ValueError(f"its identity is a {type(stored).__name__}, not a table")
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
            try:
                created = make_folders(out)
            except OSError as exc:
                raise ConfigError(f"--out {out} cannot be created: {exc.strerror or exc}") from None
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


@dataclass
class Claim:
    """A study folder held by this process (:func:`claim_folder`): the folders the claim
    created and the lock held on it."""

    out: Path
    created: list[Path]
    lock: FolderLock

    def release(self) -> None:
        self.lock.release()

    def abandon(self) -> None:
        """Leave the folder as it was found (nothing of the study in it yet): remove the
        folders this claim created, or the lock file it created, and release the lock."""
        remove_created(self.created)
        self.lock.release(remove=self.lock.created_file and not self.created)


def claim_folder(out: Path, cfg: SweepConfig, command: str | None = None) -> Claim:
    """The folder ``out`` for this study, held by this process alone: created if missing,
    locked (:class:`dockjax.io.FolderLock`; another process holding it is refused, naming
    it), then checked as :func:`prepare_folder` does. Raises ConfigError; folders it
    created are removed again unless another process holds them."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out {out} exists and is not a folder")
    try:
        created = make_folders(out)
    except OSError as exc:
        raise ConfigError(f"--out {out} cannot be created: {exc.strerror or exc}") from None
    lock = FolderLock(out, command)
    try:
        lock.acquire()
    except FolderBusyError as exc:
        raise ConfigError(str(exc)) from None
    claim = Claim(out, created, lock)
    try:
        prepare_folder(out, cfg)
    except ConfigError:
        claim.abandon()
        raise
    return claim


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
    """Run every missing chunk of the sweep in ``out`` (after :func:`claim_folder` or
    :func:`prepare_folder`), round after round (one round without racing), holding the
    folder (:class:`dockjax.io.FolderLock`) throughout. Returns the number of chunks
    computed now."""
    out = Path(out)
    with FolderLock(out):
        return _run(cfg, out, front, backend, scheduler, workers, dask_processes, progress, log)


def _run(cfg, out, front, backend, scheduler, workers, dask_processes, progress, log) -> int:
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
            for stale in folder.glob(f"{TEMP_PREFIX}*.tmp"):  # dockjax's own only
                if stale.is_dir():
                    shutil.rmtree(stale, ignore_errors=True)
                else:
                    stale.unlink(missing_ok=True)
        unit = "blocks (instance, seed)" if cfg.instances else "seeds"
        kind = (f"race over {cfg.n_blocks} {unit} (min {cfg.race['min_seeds']})" if cfg.race else
                f"{cfg.seeds} seeds" + (f" on {cfg.n_instances} instances" if cfg.instances else ""))
        log(f"sweep: {', '.join(cfg.algorithms)}; {len(cfg.settings)} settings, {kind}, {cfg.n_runs()} runs at most")
        refs = [{k: ref[k] for k in ("front", "ideal", "nadir", "hv_ref")}
                for ref in fixed_references(out, cfg, front, be, log, progress)]
        reference = refs if cfg.instances else refs[0]
        alive = np.ones(len(cfg.settings), bool)
        scores = np.full((len(cfg.settings), cfg.n_blocks), np.nan)  # HV of the plan's finished runs
        seeds_done, r = 0, 0
        bar = tqdm(total=None if cfg.race else cfg.n_runs(), unit="run", disable=not progress, file=sys.stderr,
                   dynamic_ncols=True, smoothing=0.1)

        def say(message: str) -> None:  # a line of its own, not glued to the progress bar
            bar.clear()
            log(message)
            bar.refresh()

        times: dict[tuple, list[float]] = {}
        try:
            while True:
                seeds = round_seeds(cfg, r, seeds_done, int(alive.sum()))
                if len(seeds) == 0:
                    break
                todo = []
                plan = plan_round(cfg, r, alive, seeds)
                for spec in plan:
                    data, why = read_chunk(chunks_dir / spec.name, cfg, spec)
                    if data is None:
                        todo.append(spec)
                        if why:
                            say(f"{spec.name} {why}: computed again")
                    else:
                        scores[data["setting"], blocks_of(cfg, data)] = data["HV"]
                        bar.update(spec.n_real)
                if len(todo) < len(plan):
                    say(f"round {r}: resuming, {len(plan) - len(todo)} of {len(plan)} chunks already done")
                for spec, res in be.map(run_chunk, todo, reference):
                    write_chunk(chunks_dir / spec.name, cfg, res)
                    scores[res["setting"], blocks_of(cfg, res)] = res["HV"]
                    computed += 1
                    seconds = float(res["wall_s"][0]) * len(spec.seeds)
                    key = (spec.label, spec.pop, spec.iters)
                    times.setdefault(key, []).append(seconds)
                    bar.update(spec.n_real)
                    t = times[key]
                    bar.set_postfix_str(f"{spec.label} pop {spec.pop}: " + (
                        f"first chunk (compile + run) {seconds:.1f} s" if len(t) == 1 else
                        f"{np.median(t[1:]):.2f} s/chunk"))
                    if hook and computed == hook[1]:
                        os.kill(os.getpid(), hook[0])
                seeds_done = seeds.stop
                if cfg.race is None:
                    break
                before = int(alive.sum())
                alive = decide(cfg, scores, alive, seeds_done)
                say(f"round {r}: {'blocks' if cfg.instances else 'seeds'} {seeds.start}..{seeds.stop - 1}, "
                    f"{before} settings raced, {int(alive.sum())} left")
                r += 1
                if alive.sum() <= 1 or seeds_done >= cfg.n_blocks:
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
