"""What a study runs: its settings (an algorithm, a population, an iteration count and
values for any of the algorithm's hyper-parameters), built from a design.

A design names one or more algorithms and, per algorithm, values for any field of its
``Params``: a list of values (a grid), or a range ``lo:hi`` sampled at random or by a Sobol
sequence (``samples`` points of the box of all ranges, from an explicit seed); grids and
samples combine as a cross product. Population sizes and iteration counts cross with every
setting, or a *budget* holds ``population × iterations`` at a fixed number of evaluations
(the iteration count follows the population). Several algorithms in one study are run on
the same seeds, a head-to-head.

Every name and value is checked against the algorithm's ``Params`` before any work:
unknown fields and values outside a field's range are refused, naming the field and its
allowed range (:func:`dockjax.algorithms.base.validate_params`).
"""

from __future__ import annotations

import itertools
import math
import re
from dataclasses import dataclass
from typing import Iterable, Sequence

import numpy as np
from scipy.stats import qmc

from .. import algorithms
from ..algorithms.base import coerce

__all__ = ["Setting", "ParamSpec", "parse_param", "build_settings", "FIXED_FIELDS", "symbol", "static_key"]

FIXED_FIELDS = ("pop_size", "max_iter")
"""``Params`` fields a study sets itself (population and iteration count)."""


@dataclass(frozen=True, order=True)
class Setting:
    """One configuration of an optimiser. ``params``: sorted ``(field, value)`` pairs of the
    hyper-parameters named by the study, each value in its field's type (an int for an
    integer field, else a float: :func:`dockjax.algorithms.base.coerce`). ``refine_steps``
    > 0 makes it memetic: every run's final population is polished by that many steps of
    gradient refinement (:func:`dockjax.optimize.refine_result`)."""

    algorithm: str
    pop: int
    iters: int
    params: tuple[tuple[str, float], ...] = ()
    refine_steps: int = 0

    def value(self, name: str, default=math.nan):
        return dict(self.params).get(name, default)

    @property
    def name(self) -> str:
        """The algorithm column: e.g. ``imocs``, or ``imocs+refine`` for a memetic setting."""
        return f"{self.algorithm}+refine" if self.refine_steps else self.algorithm

    @property
    def label(self) -> str:
        bits = [self.name, f"pop {self.pop}", f"{self.iters} it"]
        bits += [f"{symbol(self.algorithm, k)}={v:g}" for k, v in self.params]
        return ", ".join(bits)

    def identity(self) -> dict:
        return {"algorithm": self.algorithm, "pop": self.pop, "iters": self.iters,
                "params": {k: v for k, v in self.params}, "refine_steps": self.refine_steps}

    @classmethod
    def from_identity(cls, d: dict) -> "Setting":
        Params = algorithms.get(str(d["algorithm"])).Params
        return cls(str(d["algorithm"]), int(d["pop"]), int(d["iters"]),
                   tuple(sorted((str(k), coerce(Params, str(k), v)) for k, v in d["params"].items())),
                   int(d.get("refine_steps", 0)))

    def make_params(self):
        """The algorithm's ``Params`` of this setting (validated)."""
        try:
            return algorithms.make_params(self.algorithm, self.pop, self.iters, **dict(self.params))
        except ValueError as exc:
            raise ValueError(f"{self.algorithm}: {exc}") from None

    def is_default(self) -> bool:
        """Every named hyper-parameter at the algorithm's default."""
        defaults = algorithms.get(self.algorithm).Params()
        return all(getattr(defaults, k) == v for k, v in self.params)


def symbol(algorithm: str, field: str) -> str:
    """The paper's symbol of a ``Params`` field (its name where it has none)."""
    meta = algorithms.get(algorithm).Params.__dataclass_fields__[field].metadata
    return meta.get("symbol", field)


@dataclass(frozen=True)
class ParamSpec:
    """Values of one hyper-parameter: ``values`` (a grid) or ``lo``/``hi`` (a range to
    sample). ``algorithm`` None: every algorithm of the study that has the field."""

    field: str
    algorithm: str | None = None
    values: tuple[float, ...] = ()
    lo: float | None = None
    hi: float | None = None

    @property
    def is_range(self) -> bool:
        return self.lo is not None


NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")
"""A number as ``--param`` takes it: digits, an optional point and exponent (no ``_``,
no ``inf`` or ``nan``: Python's ``float`` accepts ``0_1`` as 1)."""


def _number(text: str) -> float:
    text = text.strip()
    if not NUMBER.fullmatch(text):
        raise ValueError(text)
    return float(text)


def parse_param(text: str) -> ParamSpec:
    """``[algorithm.]field=v1,v2,…`` (a grid) or ``[algorithm.]field=lo:hi`` (a range);
    the algorithm's name in any case. Raises ValueError naming the malformed part."""
    if "=" not in text:
        raise ValueError(f"--param {text!r}: expected NAME=VALUES, e.g. rho=0.2,0.4 or imocs.alpha_max=0.05:0.3")
    name, spec = (s.strip() for s in text.split("=", 1))
    algorithm, _, field = name.rpartition(".")
    if not field:
        raise ValueError(f"--param {text!r}: no field name before '='")
    if algorithm:
        try:
            algorithm = algorithms.get(algorithm).name
        except ValueError:
            raise ValueError(f"--param {text!r}: {algorithm!r} is not an algorithm (one of "
                             f"{', '.join(algorithms.ALGORITHMS)})") from None
    try:
        if ":" in spec:
            lo, hi = (_number(v) for v in spec.split(":"))
            if not lo < hi:
                raise ValueError
            return ParamSpec(field, algorithm or None, lo=lo, hi=hi)
        values = tuple(_number(v) for v in spec.split(","))
        if not values:
            raise ValueError
        return ParamSpec(field, algorithm or None, values=values)
    except ValueError:
        raise ValueError(f"--param {text!r}: VALUES must be numbers (such as 0.25 or 1e-3) separated by commas, or "
                         "lo:hi with lo < hi") from None


def _check_field(algorithm: str, field: str) -> None:
    fields = algorithms.get(algorithm).Params.__dataclass_fields__
    allowed = sorted(set(fields) - set(FIXED_FIELDS))
    if field in FIXED_FIELDS:
        raise ValueError(f"--param {field}: the population and iteration count are set by --pop, --iters and "
                         f"--budget")
    if field not in fields:
        raise ValueError(f"--param {field}: unknown hyper-parameter for {algorithm}; allowed: {', '.join(allowed)}")


def _samples(ranges: list[ParamSpec], n: int, design: str, seed: int) -> np.ndarray:
    """(n, len(ranges)) points of the box of the ranges: uniform at random or a scrambled
    Sobol sequence, from ``seed``."""
    d = len(ranges)
    if design == "sobol":
        u = qmc.Sobol(d, scramble=True, seed=np.random.default_rng(seed)).random(n)
    else:
        u = np.random.default_rng(seed).random((n, d))
    lo = np.array([r.lo for r in ranges])
    hi = np.array([r.hi for r in ranges])
    return lo + u * (hi - lo)


def build_settings(algorithm_names: Sequence[str], specs: Iterable[ParamSpec], pops: Sequence[int],
                   iters: Sequence[int] = (), budget: int | None = None, design: str = "grid", samples: int = 0,
                   seed: int = 0, refine_steps: int = 0) -> list[Setting]:
    """Every setting of the study, in a deterministic order (by algorithm as given, then
    population, iterations and parameter values); ``refine_steps`` makes every one memetic.
    Raises ValueError, naming the field and its allowed range, for an unknown field or an
    out-of-range value."""
    specs = list(specs)
    names = [algorithms.get(a).name for a in algorithm_names]
    if not names:
        raise ValueError("--algorithm: name at least one algorithm")
    if len(set(names)) != len(names):
        raise ValueError(f"--algorithm: {names} names an algorithm twice")
    for s in specs:
        if s.field in FIXED_FIELDS:
            _check_field(names[0], s.field)
        if s.algorithm is not None:
            if algorithms.get(s.algorithm).name not in names:
                raise ValueError(f"--param {s.algorithm}.{s.field}: {s.algorithm} is not among --algorithm {names}")
            _check_field(s.algorithm, s.field)
        elif not any(s.field in algorithms.get(a).Params.__dataclass_fields__ for a in names):
            _check_field(names[0], s.field)
    if budget is not None:
        shapes = [(p, budget // p) for p in pops]
        bad = [p for p, it in shapes if it < 1]
        if bad:
            raise ValueError(f"--budget {budget} gives no iteration at --pop {bad}")
    else:
        shapes = [(p, it) for p in pops for it in iters]
    out: list[Setting] = []
    for name in names:
        mine = {}
        for s in specs:  # an algorithm's own spec wins over a shared one
            if s.field in algorithms.get(name).Params.__dataclass_fields__ and (s.algorithm in (None, name)):
                if s.algorithm == name or s.field not in mine:
                    mine[s.field] = s
        grids = [s for s in mine.values() if not s.is_range]
        ranges = [s for s in mine.values() if s.is_range]
        if ranges and design == "grid":
            raise ValueError(f"--param {ranges[0].field}={ranges[0].lo:g}:{ranges[0].hi:g} is a range: sample it "
                             "with --design random or sobol and --samples N, or give a list of values")
        if ranges and samples < 1:
            raise ValueError("--samples must be >= 1 to sample the ranges of --param")
        sampled = _samples(ranges, samples, design, seed) if ranges else np.zeros((1, 0))
        grid_values = list(itertools.product(*[sorted(set(s.values)) for s in grids]))
        combos = set()
        Params = algorithms.get(name).Params
        for g in grid_values:
            for row in sampled:
                pairs = [*zip((s.field for s in grids), g), *zip((s.field for s in ranges), map(float, row))]
                try:
                    combos.add(tuple(sorted((k, coerce(Params, k, v)) for k, v in pairs)))
                except ValueError as exc:
                    raise ValueError(f"{name}: {exc}") from None
        for pop, it in shapes:
            for params in sorted(combos):
                setting = Setting(name, int(pop), int(it), params, int(refine_steps))
                setting.make_params()  # every value in its field's range
                out.append(setting)
    return out


def static_key(setting: Setting) -> tuple:
    """What fixes a compiled program: the algorithm, population, iterations, the static
    hyper-parameters (e.g. MOPSO's grid divisions) and the memetic finish. Settings with
    the same key share chunks."""
    fields = algorithms.get(setting.algorithm).Params.__dataclass_fields__
    statics = tuple((k, v) for k, v in setting.params if fields[k].metadata.get("static"))
    return (setting.algorithm, setting.pop, setting.iters, statics, setting.refine_steps)
