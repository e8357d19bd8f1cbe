"""Every shipped algorithm config, with a small mission for the conformance suite (a few drones,
short phases: a minute or two for the whole set)."""

from collections.abc import Callable

from omegaconf import DictConfig

from tests.conftest import CONF

SHIPPED = sorted(p.stem for p in (CONF / "algo").glob("*.yaml"))


def grid(n: int, spacing_m: float = 5.0, origin: float = -5.0) -> dict[int, list[float]]:
    return {i: [origin + spacing_m * (i // 3), origin + spacing_m * (i % 3)] for i in range(n)}


def drones(positions: dict[int, list[float]], leader: int | None = None) -> Callable[[DictConfig], None]:
    def edit(cfg: DictConfig) -> None:
        cfg.mission.initial_positions, cfg.mission.swarm_size = positions, len(positions)
        if leader is not None:
            cfg.mission.superiors = {i: (-1 if i == leader else leader) for i in positions}
        elif cfg.mission.get("superiors"):
            cfg.mission.superiors = {i: -1 for i in positions}
    return edit


def _adaptive(cfg: DictConfig) -> None:
    drones({0: [3.0, 0.0], 1: [0.0, -3.0], 2: [0.0, 3.0]}, leader=0)(cfg)
    cfg.mission.obstacles = []
    cfg.mission.max_sim_time_s = 90.0


def _with(edit: Callable[[DictConfig], None], **mission) -> Callable[[DictConfig], None]:
    def both(cfg: DictConfig) -> None:
        edit(cfg)
        for key, value in mission.items():
            cfg.mission[key] = value
    return both


DELIVERY = (["mission=delivery", "mission.generator.count=4", "mission.generator.half_size_m=15",
             "algo.params.cruise_altitude_m=4", "algo.params.altitude_step_m=1"], None)
SMALL: dict[str, tuple[list[str], Callable[[DictConfig], None] | None]] = {
    "hover": (["mission=hover", "algo.params.hover_s=1"], None),
    "crossing": (["mission=crossing", "algo.params.speed_m_s=6", "algo.params.depart_s=2"], None),
    "formation": (["mission=formation", "algo.params.start_s=2", "algo.params.radius_m=3",
                   "algo.params.angular_rate_rad_s=0.6", "algo.params.complete_after_s=15"], None),
    "formation9": (["mission=formation", "algo.params.start_s=2", "algo.params.radius_m=3",
                    "algo.params.altitude_m=4", "algo.params.angular_rate_rad_s=0.6",
                    "algo.params.complete_after_s=15"], None),
    "adaptive": (["mission=adaptive", "algo.params.goal_ne_m=[15.0,0.0]",
                  "algo.params.bounds_ne_m=[[-10.0,-20.0],[30.0,20.0]]"], _adaptive),
    "airview": (["mission=airview16"], _with(drones(grid(4, origin=0.0)), values={0: [-10.0, -10.0],
                                                                                   1: [20.0, 20.0]},
                                             max_sim_time_s=120.0)),
    "chevron": (["mission=chevron", "algo.params.radius_m=8", "algo.params.speed_m_s=2",
                 "algo.params.start_s=3", "algo.params.ramp_s=2", "algo.params.altitude_m=4"],
                _with(drones({0: [0.0, 0.0], 1: [-3.0, -3.0], 2: [-3.0, 3.0]}, leader=0),
                      max_sim_time_s=120.0)),
    "flocking": (["mission=flocking", "algo.params.flock_s=6", "algo.params.takeoff_timeout_s=15"],
                 _with(drones(grid(4)), max_sim_time_s=90.0)),
    "network": (["mission=network", "algo.params.warmup_s=2", "algo.params.phase_s=3",
                 "algo.params.schedule=[sw]", "algo.params.duration_s=10"],
                _with(drones(grid(4)), max_sim_time_s=90.0)),
    "socratic": (["mission=socratic", "algo.params.area_ne_m=[[-15.0,-15.0],[15.0,15.0]]",
                  "algo.params.coverage_goal=0.5"], _with(drones(grid(4)), max_sim_time_s=150.0)),
    "tracking": (["mission=tracking", "algo.params.start_s=3", "algo.params.duration_s=15"],
                 _with(drones(grid(4)), values={0: [-30.0, -30.0], 1: [30.0, 30.0], 2: [2, 2]},
                       max_sim_time_s=90.0)),
}


# the batch ports fly their per-drone versions' small missions
SMALL.update({f"{name}_batch": SMALL[name] for name in ("hover", "formation", "flocking")})


def small(algo: str) -> tuple[list[str], Callable[[DictConfig], None] | None]:
    """Overrides and a config edit that fly ``algo`` on a small mission."""
    overrides, edit = SMALL.get(algo, DELIVERY if algo.startswith("delivery") else (None, None))
    if overrides is None:
        raise KeyError(f"no small mission for the shipped algorithm '{algo}' in tests/testing/shipped.py")
    return [f"algo={algo}", *overrides], edit
