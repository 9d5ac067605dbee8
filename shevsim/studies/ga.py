"""ga.py - a small seeded genetic algorithm over discrete levels, with constraint handling.

Design variables are integer level indices ``x_i in {0, ..., n_i - 1}`` (gene i picks one of the
n_i discrete values beta_j of variable i). The GA minimises an objective subject to constraints
expressed as a non-negative *violation* (0 = feasible), with Deb's feasibility rules
(K. Deb, "An efficient constraint handling method for genetic algorithms", CMAME 186, 2000):

1. a feasible solution beats an infeasible one;
2. between two feasible solutions the lower objective wins;
3. between two infeasible solutions the lower violation wins.

No penalty weight to tune. Operators (defaults from seed Table A.2: population 30, 50
generations, crossover probability 0.8, mutation probability 0.01 per gene):

* selection: binary tournament under the rules above (``tournament_size`` contestants);
* crossover: with probability ``crossover_prob`` a pair exchanges genes by single-point crossover
  (``"single"``) or uniform crossover (``"uniform"``); otherwise the parents are copied;
* mutation: each gene independently, with probability ``mutation_prob``, takes a different level
  drawn uniformly;
* elitism: the ``elitism`` best solutions of a generation enter the next one unchanged;
* duplicate elimination (``unique_population``, off by default = the seed's plain GA): an
  offspring identical to a member already in the new population gets extra single-gene mutations
  until it is new (as pymoo's ``eliminate_duplicates``). With Table A.2's low mutation rate the
  plain GA collapses onto a few genomes within ~20 generations: on the 6-gene test problem it
  misses the optimum for 4 of 8 seeds (~180 distinct evaluations), and on the 8 x 8 synthetic map
  problem GA + narrowed ES ends 0.2-0.3 soot-% points short (~250-450 evaluations). With
  elimination the GA alone finds the test optimum for 15 of 16 seed/crossover runs and GA + ES
  the synthetic optimum, at ~2.5x the distinct evaluations (~650-1000). The plain GA is the
  default because the full campaign must fit ~15 minutes on 2 cores.

Evaluation is *batched*: each generation's new genomes (duplicates and genomes seen in earlier
generations removed) are passed together to ``evaluate_batch``, so a parallel runner can spread
them over workers. All randomness comes from one ``numpy.random.Generator(PCG64(seed))`` and
never from evaluation order, so the GA's path is identical for serial and parallel evaluation.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

Genome = tuple  # tuple of int level indices


@dataclass(frozen=True)
class GAConfig:
    """GA settings (defaults: seed Table A.2)."""

    population: int = 30
    generations: int = 50
    crossover_prob: float = 0.8
    mutation_prob: float = 0.01
    tournament_size: int = 2
    elitism: int = 2
    crossover: str = "single"       # or "uniform"
    unique_population: bool = False  # re-mutate an offspring that duplicates a member of the new population
    seed: int = 0

    def check(self) -> None:
        if self.population < 2:
            raise ValueError(f"GA population must be >= 2, got {self.population}")
        if self.generations < 1:
            raise ValueError(f"GA generations must be >= 1, got {self.generations}")
        for name in ("crossover_prob", "mutation_prob"):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"GA {name} must be in [0, 1], got {v}")
        if not 0 <= self.elitism < self.population:
            raise ValueError(f"GA elitism must be in [0, population), got {self.elitism}")
        if self.tournament_size < 1:
            raise ValueError(f"GA tournament_size must be >= 1, got {self.tournament_size}")
        if self.crossover not in ("single", "uniform"):
            raise ValueError(f"GA crossover must be 'single' or 'uniform', got {self.crossover!r}")


@dataclass
class GAResult:
    """Outcome of :func:`run_ga`.

    Attributes
    ----------
    best : tuple of int
        Best genome found (feasibility rules).
    best_objective, best_violation : float
    evaluated : dict
        Every distinct genome evaluated -> (objective, violation).
    history : list of dict
        Per generation: best objective/violation, number of feasible members, new evaluations.
    """

    best: Genome
    best_objective: float
    best_violation: float
    evaluated: dict = field(default_factory=dict)
    history: list = field(default_factory=list)

    def ranked(self, feasible_only: bool = True) -> list[tuple[Genome, float, float]]:
        """Evaluated genomes sorted best first (feasibility rules; ties broken by genome)."""
        rows = [(g, o, v) for g, (o, v) in self.evaluated.items() if not feasible_only or v <= 0.0]
        return sorted(rows, key=lambda r: rank_key(r[1], r[2], r[0]))


def rank_key(objective: float, violation: float, genome=()) -> tuple:
    """Sort key implementing the feasibility rules (smaller is better); NaN counts as worst."""
    if violation is None or math.isnan(violation):
        violation = math.inf
    if objective is None or math.isnan(objective):
        objective = math.inf
    if violation > 0.0:
        return (1, violation, objective, tuple(genome))
    return (0, objective, 0.0, tuple(genome))


def run_ga(n_levels: Sequence[int],
           evaluate_batch: Callable[[list[Genome]], list[tuple[float, float]]],
           config: GAConfig = GAConfig(),
           initial: Sequence[Genome] = (),
           callback: Callable[[int, GAResult], None] | None = None) -> GAResult:
    """Minimise over discrete genomes with a seeded GA.

    Parameters
    ----------
    n_levels : sequence of int
        Number of levels of each gene (each >= 1).
    evaluate_batch : callable
        ``list of genomes -> list of (objective, violation)`` in the same order; violation >= 0,
        0 meaning feasible. Called once per generation with the genomes not evaluated before.
    config : GAConfig
    initial : sequence of genomes
        Genomes placed in the first population (e.g. a known good constant map); the rest random.
    callback : callable, optional
        ``callback(generation, partial_result)`` after each generation.
    """
    config.check()
    n_levels = [int(n) for n in n_levels]
    if not n_levels or min(n_levels) < 1:
        raise ValueError(f"GA needs at least one gene with >= 1 level, got {n_levels}")
    rng = np.random.Generator(np.random.PCG64(config.seed))
    n_genes = len(n_levels)
    hi = np.array(n_levels)
    memo: dict[Genome, tuple[float, float]] = {}
    result = GAResult(best=(), best_objective=math.inf, best_violation=math.inf, evaluated=memo)

    def score(pop: list[Genome]) -> list[tuple[float, float]]:
        new = list(dict.fromkeys(g for g in pop if g not in memo))
        if new:
            vals = evaluate_batch(new)
            if len(vals) != len(new):
                raise ValueError(f"evaluate_batch returned {len(vals)} values for {len(new)} genomes")
            for g, (o, v) in zip(new, vals):
                memo[g] = (float(o), max(0.0, float(v)))
        return [memo[g] for g in pop], len(new)

    pop: list[Genome] = []
    for g in initial:
        g = tuple(int(x) for x in g)
        if len(g) != n_genes or any(not 0 <= x < n for x, n in zip(g, n_levels)):
            raise ValueError(f"initial genome {g} does not fit levels {n_levels}")
        if len(pop) < config.population:
            pop.append(g)
    while len(pop) < config.population:
        pop.append(tuple(int(x) for x in rng.integers(0, hi)))

    n_space = math.prod(n_levels)
    mutable = [j for j, n in enumerate(n_levels) if n > 1]

    def tournament(fit) -> int:
        idx = rng.integers(0, len(pop), size=config.tournament_size)
        return min(idx, key=lambda i: rank_key(fit[i][0], fit[i][1], pop[i]))

    for gen in range(config.generations):
        fit, n_new = score(pop)
        order = sorted(range(len(pop)), key=lambda i: rank_key(fit[i][0], fit[i][1], pop[i]))
        b = order[0]
        if rank_key(fit[b][0], fit[b][1], pop[b]) < rank_key(result.best_objective, result.best_violation, result.best):
            result.best, result.best_objective, result.best_violation = pop[b], fit[b][0], fit[b][1]
        result.history.append({"generation": gen, "best_objective": fit[b][0], "best_violation": fit[b][1],
                               "n_feasible": sum(1 for o, v in fit if v <= 0.0), "new_evaluations": n_new,
                               "total_evaluations": len(memo)})
        if callback is not None:
            callback(gen, result)
        if gen == config.generations - 1:
            break
        nxt = [pop[i] for i in order[:config.elitism]]
        seen = set(nxt)
        while len(nxt) < config.population:
            p1 = list(pop[tournament(fit)])
            p2 = list(pop[tournament(fit)])
            if n_genes > 1 and rng.random() < config.crossover_prob:
                if config.crossover == "single":
                    cut = int(rng.integers(1, n_genes))
                    p1[cut:], p2[cut:] = p2[cut:], p1[cut:]
                else:
                    swap = rng.random(n_genes) < 0.5
                    for j in np.flatnonzero(swap):
                        p1[j], p2[j] = p2[j], p1[j]
            for child in (p1, p2):
                for j in range(n_genes):
                    if n_levels[j] > 1 and rng.random() < config.mutation_prob:
                        _mutate(child, j, n_levels, rng)
                if config.unique_population and n_space > config.population:
                    tries = 0
                    while tuple(child) in seen and tries < 20:
                        _mutate(child, int(rng.choice(mutable)), n_levels, rng)
                        tries += 1
                if len(nxt) < config.population:
                    nxt.append(tuple(int(x) for x in child))
                    seen.add(nxt[-1])
        pop = nxt
    return result


def _mutate(child: list, j: int, n_levels, rng) -> None:
    """Gene j takes a different level, drawn uniformly."""
    r = int(rng.integers(0, n_levels[j] - 1))
    child[j] = r if r < child[j] else r + 1


# -- steps 2 and 3 of the three-step optimisation (seed A.3) ----------------------------------------
def narrow_bounds(ranked: Sequence[Genome], n_levels: Sequence[int], top_k: int = 10,
                  max_cases: int | None = 1000, grow: bool = False) -> tuple[list[tuple[int, int]], int]:
    """Step 2: per-gene [lo, hi] level bounds = min/max over the ``k`` best genomes.

    ``k`` starts at ``top_k`` and is reduced until the narrowed space has at most ``max_cases``
    combinations (never below 1: the best genome alone gives a single case). With ``grow`` (and a
    ``max_cases``), ``k`` then grows past ``top_k`` while the space stays within ``max_cases``: the
    exhaustive search gets as many cases as the cap allows (the seed's 648), not only the box of the
    ``top_k`` best, which a converged GA makes small.

    Returns
    -------
    bounds : list of (lo, hi) inclusive level indices per gene
    k : number of genomes used
    """
    ranked = [tuple(g) for g in ranked]
    if not ranked:
        raise ValueError("narrow_bounds: no candidate solutions (no feasible GA solution?)")
    def box(k):
        top = np.array(ranked[:k])
        return [(int(top[:, j].min()), int(top[:, j].max())) for j in range(len(n_levels))]

    k = min(top_k, len(ranked))
    while True:
        bounds = box(k)
        if max_cases is None or k == 1 or space_size(bounds) <= max_cases:
            break
        k -= 1
    if grow and max_cases is not None:
        while k < len(ranked) and space_size(box(k + 1)) <= max_cases:
            k += 1
        bounds = box(k)
    return bounds, k


def space_size(bounds: Sequence[tuple[int, int]]) -> int:
    """Number of combinations in inclusive per-gene bounds."""
    return int(np.prod([hi - lo + 1 for lo, hi in bounds], dtype=object))


def exhaustive_genomes(bounds: Sequence[tuple[int, int]]) -> list[Genome]:
    """Step 3: every genome inside the bounds (lexicographic order)."""
    import itertools
    return [tuple(g) for g in itertools.product(*[range(lo, hi + 1) for lo, hi in bounds])]
