"""The solver settings of a run, light to import (the settings module builds on them; no compiled code here)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from pipeline.routing.contract import UnknownSolverError

if TYPE_CHECKING:
    from pipeline.routing.engine_limits import EngineLimits


# the registered solvers (pipeline.routing.solvers.SOLVERS, which checks it holds exactly these), named here so a
# run can refuse an unknown one before anything is loaded or opened
SOLVER_NAMES = ("bfoa", "dp", "astar", "gc", "rhumb")
# the product's defaults for a solver's own options, where they differ from the library's: `dp` certifies its plan
# within 0.1 % of the optimum instead of keeping every label, and its optimum is over plans that may wait (heave to)
# at a node under weather that changes in time: the label DP's wait-free plan first, then the grid DP over the
# departure times of a 1 h grid (coarser on voyages over 240 h: RTA / 240 in whole hours) and of that plan, waiting
# up to 6 h beyond the next grid time (dp_grid.py). The label DP's work is paced by legs sailed: past 3,000,000 legs
# (about 11 s of CPU; a 5,000 NM storm voyage needs 10 million to keep every label) it searches again keeping at most
# 128 labels per node, and the plan's reason says so
DEFAULT_SOLVER_OPTIONS = {"dp": {"gap": 1e-3, "slot_h": 1.0, "max_wait_h": 6.0, "wait_free_first": True,
                                 "slots_per_rta": 240, "max_label_legs": 3_000_000, "capped_labels": 128}}
# and where the plan's route is searched again on finer corridors (refine_split > 1): the swarm's plan is polished by
# the DP once on the graph, not up to 6 times, for the corridors walk the route on (refine_graph.py). On the routing
# suite (10 seeds) the refined plans' median gaps are the same or better for 18 % less CPU (bench/README.md)
REFINED_SOLVER_OPTIONS = {"bfoa": {"polish_rounds": 1}}


@dataclass(frozen=True)
class DpOptions:
    """The options of `--solver dp` (pipeline/routing/dp.py; the product's values: DEFAULT_SOLVER_OPTIONS)."""

    upper_bound: float | None = None  # a known plan's cost, to prune with (the baseline's is always used)
    incumbent: str | None = "bfoa"  # also prune with this solver's plan (seed 1, default options); None: no
    gap: float = 0.0  # > 0: the plan costs at most (1 + gap) × the optimum. Labels: ε-trimming (see `trim_eps`),
    #                   certified under the dominance's assumption; grid (slot_h): pruning, certified outright
    slot_h: float | None = None  # a number: the exact DP of dp_grid.py, departures from nodes on this time grid
    #                              (h) with waits; the plan's legs then carry their waits (wait_h, wait_fuel_t)
    max_wait_h: float = 0.0  # grid: a ship may wait this long beyond the first slot after arriving at a node
    wait_tph: float | None = None  # grid: fuel rate while waiting (t/h); None: calm water at the lowest setting
    wait_free_first: bool = False  # grid: first the label DP (same gap); its plan's times join the grid
    slots_per_rta: float | None = None  # grid: a step of at least the RTA's passage hours / this, in whole hours
    max_label_legs: int | None = None  # the label DP gives up after sailing this many legs (None: never) and
    #                                     searches again keeping at most `capped_labels` labels per node (approximate;
    #                                     the plan's reason says so): its work paced by legs sailed, not the clock
    capped_labels: int = 64

    def __post_init__(self):
        legs, cap = self.max_label_legs, self.capped_labels
        if legs is not None:
            if isinstance(legs, bool) or not isinstance(legs, (int, float)) or not legs >= 1:
                raise ValueError(f"dp option max_label_legs must be a number of legs ≥ 1 or none, got {legs!r}")
            object.__setattr__(self, "max_label_legs", int(legs))
        if isinstance(cap, bool) or not isinstance(cap, (int, float)) or not cap >= 1 or int(cap) != cap:
            raise ValueError(f"dp option capped_labels must be a whole number of labels per node ≥ 1, got {cap!r}")
        object.__setattr__(self, "capped_labels", int(cap))


@dataclass(frozen=True)
class RoutingOptions:
    """Solver settings of a run (see pipeline.routing.solve); the settings' `routing` section extends them."""

    solver: str = "bfoa"
    # the solver's own options as (name, value) pairs over the product defaults (DEFAULT_SOLVER_OPTIONS), e.g.
    # (("gap", "0"),) for an exact dp; values may be text (`--solver-option gap=0`)
    solver_options: tuple = ()
    objective: str = "jit"
    arrival_window_h: float = 6.0
    seed: int = 1
    n_lines: int | None = None  # None: chosen from the voyage length
    n_points: int = 21
    d_point_nm: float | None = None
    land_clearance_nm: float = 2.0  # legs keep this far from land (checked at ≤ 0.1 NM) ...
    port_approach_nm: float = 10.0  # ... except within this distance of a port, where they need only be at sea
    # engine-change limits (engine_limits.py): every rpm setting of a plan is held at least this long, and each
    # change costs this much fuel in the objective (0 and 0: the solver's plan as found, a setting per leg)
    min_engine_hold_h: float = 12.0
    engine_change_cost_t: float = 0.05
    # speed between the lowest and the highest allowed rpm, refined per run of a setting after the search
    # (continuous_speed.py); False: plans use only the listed settings and the constant rpm meeting the RTA
    continuous_speed: bool = True
    # after the search, the plan's route is searched again on a graph this many times finer across the lines, in a
    # corridor of ±1 node round it, re-centred while that gains (refine_graph.py); 1: the graph's plan as found
    refine_split: int = 3
    # a lagged ensemble of this many cycles (the one routed on and the complete ones before it) sails each plan and
    # its baseline (ensemble.py): P(on time), fuel and saving P10/P50/P90 stored with the plan; 0: none
    ensemble_members: int = 4
    # robust decisions over that ensemble (robust.py; none acts with fewer than two members): aim this many standard
    # deviations of the plan's arrival across the members before the RTA (at most arrival_margin_max_share of the
    # passage; 0: aim at the RTA) ...
    arrival_margin_sigmas: float = 0.0
    arrival_margin_max_share: float = 0.05
    # ... with a calibrated error model, sized by the error no later re-plan corrects (None: the whole passage's): the
    # error of the last this many hours (about the cycle interval), or what of the whole passage's error the ship's
    # speed reserve cannot make up, whichever is more ...
    arrival_margin_horizon_h: float | None = None
    # ... keep the constant-speed baseline unless the plan beats it in at least this share of the members (0: off) ...
    min_win_share: float = 0.0
    # ... and at sea keep the current plan unless the new one gains more than this many standard deviations of its
    # gain across the members, or is on time in more of them (0: always take the new plan)
    replan_gain_sigmas: float = 0.0
    # passages (pipeline.routing.passages names, e.g. ("suez",)) the base route keeps out of: round the Cape instead
    # of Suez. Per fleet in the settings (JITROUTE_AVOID_PASSAGES=suez,panama), per voyage with `route --avoid`
    avoid_passages: tuple = ()

    def __post_init__(self):
        if self.solver not in SOLVER_NAMES:
            raise UnknownSolverError(f"unknown solver {self.solver!r}; use one of {', '.join(SOLVER_NAMES)}")
        object.__setattr__(self, "solver_options", tuple((str(k), v) for k, v in dict(self.solver_options).items()))
        if isinstance(self.refine_split, bool) or not isinstance(self.refine_split, int) or self.refine_split < 1:
            raise ValueError(f"refine_split must be a whole number ≥ 1 (1: no refinement), not {self.refine_split!r}")
        from pipeline.routing.passages import check_avoid  # plain data, no compiled code

        object.__setattr__(self, "avoid_passages", tuple(sorted(check_avoid(self.avoid_passages))))

    def solver_overrides(self) -> dict:
        """The solver's option values of this run: the product defaults (with the refinement's when it refines), then
        `solver_options`."""
        refined = REFINED_SOLVER_OPTIONS.get(self.solver, {}) if self.refine_split > 1 else {}
        return {**DEFAULT_SOLVER_OPTIONS.get(self.solver, {}), **refined, **dict(self.solver_options)}

    @property
    def limits(self) -> "EngineLimits":
        from pipeline.routing.engine_limits import EngineLimits  # compiled kernels: loaded when routing

        return EngineLimits(min_hold_h=float(self.min_engine_hold_h), change_cost_t=float(self.engine_change_cost_t))

    @classmethod
    def from_settings(cls, routing_settings, **overrides) -> "RoutingOptions":
        """From an object with these attribute names (the settings' routing section); None overrides are ignored."""
        values = {k: getattr(routing_settings, k) for k in cls.__dataclass_fields__}
        values.update({k: v for k, v in overrides.items() if v is not None})
        return cls(**values)
