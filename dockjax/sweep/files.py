"""A study folder's chunk files: each one proves what it is.

A chunk file records, under its checksum (:func:`dockjax.io.atomic_savez`), the identity of
its study (a hash of the configuration, :func:`study_hash`), its round and index, and the
setting and seed of every row. :func:`read_chunk` accepts a file only when all of it matches
the chunk the study's plan expects at that place; anything else — no checksum, another
study's file, a file of another round or place, other runs — is not a result, and the
caller recomputes the chunk (the reason says why).
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from ..io import DamagedFileError, atomic_savez, load_npz
from .config import ChunkSpec, SweepConfig, blocks_of, plan_round, round_seeds
from .race import decide

__all__ = ["DamagedFileError", "load_npz", "study_hash", "write_chunk", "read_chunk", "finished_chunks",
           "reference_path"]


def reference_path(out: Path, instance: int = -1) -> Path:
    """Where a study keeps the reference of ``instance`` (-1: the preset's own move):
    ``reference.npz``, or ``references/instance-<k>.npz`` in a study over instances."""
    return Path(out) / "reference.npz" if instance < 0 else Path(out) / "references" / f"instance-{instance:05d}.npz"


def study_hash(cfg: SweepConfig) -> str:
    """SHA-256 of the study's identity (:meth:`SweepConfig.identity`, sorted JSON)."""
    return hashlib.sha256(json.dumps(cfg.identity(), sort_keys=True).encode()).hexdigest()


def write_chunk(path: Path, cfg: SweepConfig, columns: dict[str, np.ndarray]) -> Path:
    """A finished chunk's columns (:func:`dockjax.sweep.run_chunk`), stamped with the
    study's hash, written atomically with its checksum."""
    return atomic_savez(path, {**columns, "study": np.asarray(study_hash(cfg))})


def read_chunk(path: Path, cfg: SweepConfig, spec: ChunkSpec) -> tuple[dict[str, np.ndarray] | None, str | None]:
    """``(columns, None)`` when ``path`` is the finished chunk ``spec`` of this study;
    ``(None, None)`` when there is no file; ``(None, reason)`` when there is one that must
    not be read as this chunk's result."""
    if not path.exists():
        return None, None
    try:
        z = load_npz(path, require_checksum=True)
        study, rounds, index = str(z["study"]), z["round"], z["chunk"]
        settings, seeds = z["setting"], z["seed"]
    except DamagedFileError as exc:
        return None, f"damaged ({exc})"
    except KeyError as exc:
        return None, f"incomplete (no {exc.args[0]!r})"
    if study != study_hash(cfg):
        return None, "belongs to another study"
    if not (np.all(rounds == spec.round) and np.all(index == spec.index)):
        return None, f"holds round {rounds[:1].tolist()} chunk {index[:1].tolist()}, not this place's"
    if tuple(settings.tolist()) != spec.settings[:spec.n_real] or tuple(seeds.tolist()) != spec.seeds[:spec.n_real]:
        return None, "holds other runs than this chunk's"
    instance = z["instance"] if "instance" in z else np.full(len(seeds), -1)
    if not np.all(instance == spec.instance):
        return None, f"holds instance {instance[:1].tolist()}, not this chunk's {spec.instance}"
    return z, None


def finished_chunks(cfg: SweepConfig, out: Path) -> list[tuple[ChunkSpec, dict[str, np.ndarray]]]:
    """Every chunk of the study's plan, read from ``out/chunks`` in plan order (round by
    round; a race's rounds decided by :func:`dockjax.sweep.race.decide` on the scores read
    so far, as the sweep decided them). Files that are not part of the plan are not read.
    Raises RuntimeError naming the first planned chunk that is missing or not valid (the
    study is not finished: run it again)."""
    chunks = Path(out) / "chunks"
    alive = np.ones(len(cfg.settings), bool)
    scores = np.full((len(cfg.settings), cfg.n_blocks), np.nan)
    found: list[tuple[ChunkSpec, dict[str, np.ndarray]]] = []
    done, r = 0, 0
    while True:
        seeds = round_seeds(cfg, r, done, int(alive.sum()))
        if len(seeds) == 0:
            break
        for spec in plan_round(cfg, r, alive, seeds):
            data, why = read_chunk(chunks / spec.name, cfg, spec)
            if data is None:
                raise RuntimeError(f"{chunks / spec.name} {why or 'is missing'}: the study is not finished; run its "
                                   "command again to complete it")
            scores[data["setting"], blocks_of(cfg, data)] = data["HV"]
            found.append((spec, data))
        done = seeds.stop
        if cfg.race is None:
            break
        alive = decide(cfg, scores, alive, done)
        r += 1
        if alive.sum() <= 1 or done >= cfg.n_blocks:
            break
    return found
