"""The reference front of a sweep, fixed before its first run and stored in its folder
(conventions §8): the best-known front of the problem by default (an ε-constraint sweep
with gradient refinement that sees no optimiser's front, computed once per problem
definition and cached on disk by its identity), a pilot of the study's first algorithm, or a
user's file. ``reference.npz`` records the front, its ideal and nadir (the normalisation of
every indicator), the hypervolume reference point, the kind and, for the best-known front,
its trajectories ``X``. A study over instances fixes one reference per instance, in
``references/instance-<k>.npz`` (:func:`fixed_references`): each instance's indicators are
normalised by its own front."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Callable

import numpy as np

from .. import config
from ..best_known import best_known_cached, fronts_cache
from ..io import atomic_savez
from ..metrics import nondominated_points
from .config import PILOT_SEED0, ConfigError, SweepConfig, pilot_spec, refine_rows
from .execute import problem_of, run_chunk
from .files import DamagedFileError, load_npz, reference_path

__all__ = ["fixed_reference", "fixed_references"]


def fixed_references(out: Path, cfg: SweepConfig, front: np.ndarray | None, backend,
                     log: Callable[[str], None], progress: bool = False) -> list[dict]:
    """The study's references: ``[fixed_reference(...)]`` without instances, else one per
    instance (each made now if it does not exist yet, then reused unchanged), with a line
    per instance naming it."""
    if not cfg.instances:
        return [fixed_reference(out, cfg, front, backend, log, progress)]
    (out / "references").mkdir(exist_ok=True)
    refs = []
    for k, inst in enumerate(cfg.instances):
        def say(message: str, k=k, name=inst.name) -> None:
            log(f"instance {k + 1}/{len(cfg.instances)} ({name}): {message}")
        refs.append(fixed_reference(out, cfg, None, backend, say, progress, instance=k))
    return refs


def fixed_reference(out: Path, cfg: SweepConfig, front: np.ndarray | None, backend,
                    log: Callable[[str], None], progress: bool = False, instance: int = -1) -> dict:
    """``out/reference.npz`` (of ``instance``: :func:`reference_path`), made now if it does
    not exist yet (then reused unchanged); ``progress``: a bar on stderr while a best-known
    front is computed."""
    path = reference_path(out, instance)
    if path.exists():
        try:
            ref = load_npz(path)
            log(f"reference: {len(ref['front'])} points ({ref['source']}) from {path} (fixed at sweep start)")
            return ref
        except (DamagedFileError, KeyError) as exc:
            if cfg.reference["kind"] == "file" and front is None:
                raise ConfigError(f"{exc}; it was made from --reference-front: pass that file again") from None
            log(f"reference: {path} is damaged; made again ({cfg.reference['kind']}, deterministic)")
    t0 = time.perf_counter()
    kind = cfg.reference["kind"]
    extra = {}
    if kind == "best-known":
        cache = fronts_cache()
        try:
            cache.mkdir(parents=True, exist_ok=True)
        except OSError:
            cache = None
        settings = {k: cfg.reference[k] for k in config.BEST_KNOWN}
        # with memetic settings, the front's polishing shares their compiled shape
        rows = refine_rows(cfg) if any(s.refine_steps for s in cfg.settings) else None
        spec = pilot_spec(cfg, instance)  # the instance's problem, as the chunks build it
        best = best_known_cached(problem_of(cfg.preset, cfg.n_control, spec.instance_fields), cache, log=log,
                                 progress=progress, rows=rows, **settings)
        front, idx = nondominated_points(best.F, return_index=True)
        extra["X"] = best.X[idx]
    elif kind == "pilot":
        spec = pilot_spec(cfg, instance)
        log(f"reference: pilot of {spec.n_real} {spec.algorithm} runs (pop {spec.pop}, {spec.iters} iterations, "
            f"default hyper-parameters, seeds {PILOT_SEED0}..) ...")
        _, res = next(backend.map(run_chunk, [spec]))
        front = nondominated_points(res["front_F"])
    if len(front) == 0:
        if instance >= 0:
            raise RuntimeError(f"the reference ({kind}) of instance {cfg.instances[instance].name!r} holds no feasible "
                               "trajectory; raise --iters or use --reference best-known")
        raise RuntimeError(f"the reference ({kind}) holds no feasible trajectory; raise --iters or pass "
                           "--reference-front")
    ref = {"front": front, "ideal": front.min(0), "nadir": front.max(0), "hv_ref": np.float64(config.HV_REFERENCE),
           "source": np.asarray(kind), **extra}
    atomic_savez(path, ref)
    log(f"reference: {len(front)} points ({kind}) in {time.perf_counter() - t0:.1f} s; ideal "
        f"{np.round(ref['ideal'], 4).tolist()}, nadir {np.round(ref['nadir'], 4).tolist()}")
    return ref
