"""Never losing work: the results folder is checked before anything runs, every finished
chunk is written atomically, and a re-run computes only the chunks that are missing."""

from __future__ import annotations

import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable

import jax
import numpy as np
from tqdm import tqdm

from .. import config
from ..io import atomic_savez, atomic_write_text
from ..metrics import nondominated_points
from ..version import __version__
from .config import PILOT_SEED0, ConfigError, SweepConfig, pilot_spec, plan_chunks
from .execute import DaskBackend, LocalBackend, run_chunk
from .files import load_npz

__all__ = ["prepare_folder", "remove_created", "run_sweep"]


def _diff(a: dict, b: dict) -> list[str]:
    keys = sorted(set(a) | set(b))
    return [f"{k}: folder has {a.get(k)!r}, command gives {b.get(k)!r}" for k in keys if a.get(k) != b.get(k)]


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
                _check_chunks(out, cfg)
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


def _check_chunks(out: Path, cfg: SweepConfig) -> None:
    plan = {c.name: c for c in plan_chunks(cfg)}
    folder = out / "chunks"
    if not folder.is_dir():
        return
    for path in sorted(folder.glob("chunk-*.npz")):
        spec = plan.get(path.name)
        if spec is None:
            raise ConfigError(f"--out {out}: {path.name} is not part of this sweep's plan; use another folder")
        try:
            with np.load(path, allow_pickle=False) as z:
                ids = tuple(int(i) for i in z["run_id"])
        except Exception:  # unreadable: recomputed later
            continue
        if ids != spec.run_ids:
            raise ConfigError(f"--out {out}: {path.name} holds other runs than this sweep's plan; use another folder")


def _write_config(out: Path, cfg: SweepConfig) -> None:
    path = out / "config.json"
    if path.exists():
        return
    doc = {"identity": cfg.identity(),
           "info": {"dockjax": __version__, "jax": jax.__version__, "numpy": np.__version__,
                    "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "argv": sys.argv}}
    atomic_write_text(path, json.dumps(doc, indent=2) + "\n")


def _reference(out: Path, cfg: SweepConfig, front: np.ndarray | None, backend, log) -> dict:
    path = out / "reference.npz"
    if path.exists():
        ref = load_npz(path)
        log(f"reference: {len(ref['front'])} points from {path} (fixed at sweep start)")
        return ref
    t0 = time.perf_counter()
    if front is None:
        spec = pilot_spec(cfg)
        log(f"reference: pilot of {spec.n_real} {cfg.algorithm} runs (pop {spec.pop}, {cfg.iters} iterations, "
            f"{'ρ=0.4, α_max=0.1, ' if cfg.has_grid else ''}seeds {PILOT_SEED0}..) ...")
        _, res = next(backend.map(run_chunk, [spec]))
        front = nondominated_points(res["front_F"])
        if len(front) == 0:
            raise RuntimeError("the reference pilot found no feasible trajectory; raise --iters or "
                               "pass --reference-front")
        source = "pilot"
    else:
        source = "file"
    ref = {"front": front, "ideal": front.min(0), "nadir": front.max(0), "hv_ref": np.float64(config.HV_REFERENCE),
           "source": np.asarray(source)}
    atomic_savez(path, ref)
    log(f"reference: {len(front)} points ({source}) in {time.perf_counter() - t0:.1f} s"
        f"{' (compile included)' if source == 'pilot' else ''}; ideal {np.round(ref['ideal'], 4).tolist()}, "
        f"nadir {np.round(ref['nadir'], 4).tolist()}")
    return ref


def run_sweep(cfg: SweepConfig, out: Path, *, front: np.ndarray | None = None, backend: str = "local",
              scheduler: str | None = None, workers: int = 2, dask_processes: bool = False,
              progress: bool = True, log: Callable[[str], None] = print) -> int:
    """Run every missing chunk of the sweep in ``out`` (after :func:`prepare_folder`).
    Returns the number of chunks computed now."""
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
    pause = float(os.environ.get("DOCKJAX_SWEEP_PAUSE", "0") or 0)
    try:
        _write_config(out, cfg)
        chunks_dir.mkdir(exist_ok=True)
        for stale in chunks_dir.glob(".chunk-*.tmp"):  # left by a kill during a write
            stale.unlink(missing_ok=True)
        plan = plan_chunks(cfg)
        done = {c.index for c in plan if _readable(chunks_dir / c.name)}
        todo = [c for c in plan if c.index not in done]
        n_total = sum(c.n_real for c in plan)
        n_done = sum(c.n_real for c in plan if c.index in done)
        log(f"sweep: {plan[0].label if plan else cfg.algorithm}, {cfg.n_runs()} runs "
            f"({len(cfg.settings())} settings × {cfg.seeds} seeds, "
            f"{cfg.iters} iterations) in {len(plan)} chunks of {len(plan[0].seeds)}; "
            + (f"resuming: {len(done)} of {len(plan)} chunks already done" if done else "starting"))
        ref = _reference(out, cfg, front, be, log)
        if not todo:
            return 0
        reference = {k: ref[k] for k in ("front", "ideal", "nadir", "hv_ref")}
        bar = tqdm(total=n_total, initial=n_done, unit="run", disable=not progress, file=sys.stderr,
                   dynamic_ncols=True, smoothing=0.1)
        times: dict[int, list[float]] = {}
        try:
            for spec, res in be.map(run_chunk, todo, reference):
                atomic_savez(chunks_dir / spec.name, res)
                seconds = float(res["wall_s"][0]) * len(spec.seeds)
                first = spec.pop not in times
                times.setdefault(spec.pop, []).append(seconds)
                bar.update(spec.n_real)
                if first:
                    bar.set_postfix_str(f"first chunk of pop {spec.pop} (compile + run): {seconds:.1f} s")
                else:
                    t = times[spec.pop]
                    bar.set_postfix_str(f"pop {spec.pop}: compile ≈ {max(t[0] - np.median(t[1:]), 0):.1f} s, "
                                        f"{np.median(t[1:]):.2f} s/chunk")
                if pause:
                    time.sleep(pause)
        finally:
            bar.close()
        for pop, t in times.items():
            rest = np.median(t[1:]) if len(t) > 1 else 0.0
            later = f", later chunks {rest:.2f} s each (compile ≈ {max(t[0] - rest, 0):.1f} s)" if len(t) > 1 else ""
            log(f"pop {pop}: first chunk {t[0]:.1f} s{later}")
        return len(todo)
    finally:
        be.close()


def _readable(path: Path) -> bool:
    if not path.exists():
        return False
    try:
        with np.load(path, allow_pickle=False) as z:
            z["run_id"], z["front_offsets"]
        return True
    except Exception:
        return False
