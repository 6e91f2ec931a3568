"""Islands and bridges: a 2D navigation task whose safe region is a union of convex pieces.

Thesis section "Islands and Bridges" (chapter 7): the state is a position on a plane
made of islands (discs or boxes) joined by narrow bridges (boxes); stepping off the
union of these pieces is a failure, like dropping a grasped object. The environment
exposes its one-step prediction and the signed distance ``M(s)`` to the edge of the safe
region, so that shields (``shields.SimpleShield``, ``shields.SmartShield``) can correct
unsafe actions before they are executed.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import ArrayLike, NDArray

from envs.geometry import Box, Disc, Piece, point_depth, point_signed_distance, signed_distance

__all__ = [
    "DEFAULT_BRIDGES",
    "DEFAULT_ISLANDS",
    "RING_BRIDGES",
    "RING_ISLANDS",
    "SPUR_BRIDGES",
    "SPUR_ISLANDS",
    "IslandsBridges",
    "draw_map",
]

#: The ring map's islands (``ihm/IslandsBridgesRing-v0``), in map units (the plane spans
#: [0.1, 1.9] x [0.15, 1.85]): I0 south-west disc, I1 south-east box, I2 north-east disc,
#: I3 north-west box.
RING_ISLANDS: tuple[Piece, ...] = (
    Disc(center=(0.4, 0.4), radius=0.3),
    Box(lo=(1.3, 0.15), hi=(1.9, 0.65)),
    Disc(center=(1.6, 1.55), radius=0.3),
    Box(lo=(0.1, 1.2), hi=(0.7, 1.8)),
)

#: The ring map's bridges, all 0.1 wide, forming a ring (a cycle of grasps, as in continuous
#: in-hand rotation): B0 I0-I1, B1 I1-I2, B2 I0-I3, B3 I3-I2.
RING_BRIDGES: tuple[Piece, ...] = (
    Box(lo=(0.6, 0.35), hi=(1.35, 0.45)),
    Box(lo=(1.55, 0.6), hi=(1.65, 1.3)),
    Box(lo=(0.35, 0.65), hi=(0.45, 1.25)),
    Box(lo=(0.65, 1.5), hi=(1.35, 1.6)),
)

#: The five-island map (``ihm/IslandsBridges-v0``, the first shipped map): the ring plus a dead
#: end, the central island I4 ``Disc((1.0, 1.0), 0.2)`` reached only by the spur B4
#: ``Box((0.95, 0.35), (1.05, 0.85))`` that leaves B0 at a T-junction. From I4 every goal lies
#: behind the agent's back, so a policy must first walk away from it.
SPUR_ISLANDS: tuple[Piece, ...] = (*RING_ISLANDS, Disc(center=(1.0, 1.0), radius=0.2))
SPUR_BRIDGES: tuple[Piece, ...] = (*RING_BRIDGES, Box(lo=(0.95, 0.35), hi=(1.05, 0.85)))

#: The default map, used when ``IslandsBridges`` gets no map: the v0 map (``SPUR_ISLANDS``).
DEFAULT_ISLANDS: tuple[Piece, ...] = SPUR_ISLANDS
#: The default map's bridges: the v0 map (``SPUR_BRIDGES``).
DEFAULT_BRIDGES: tuple[Piece, ...] = SPUR_BRIDGES

# Colours of the rgb_array rendering (thesis figure: red = current state, blue = goal).
_SEA = np.array([205, 222, 235], dtype=np.uint8)
_LAND = np.array([236, 216, 165], dtype=np.uint8)
_SHORE = np.array([90, 80, 60], dtype=np.uint8)
_GOAL = np.array([30, 80, 220], dtype=np.uint8)
_AGENT = np.array([220, 30, 30], dtype=np.uint8)


def _dist(x0: float, y0: float, x1: float, y1: float) -> float:
    """``np.linalg.norm((x0 - x1, y0 - y1))`` in floats (``sqrt(dx*dx + dy*dy)``, how numpy
    reduces two components; the same value to the last bit, tested)."""
    dx, dy = x0 - x1, y0 - y1
    return math.sqrt(dx * dx + dy * dy)


def _area(piece: Piece) -> float:
    if isinstance(piece, Disc):
        return math.pi * piece.radius**2
    lo, hi = piece.bounds()
    return float(np.prod(hi - lo))


def _check_pieces(name: str, pieces: Sequence[Piece]) -> tuple[Piece, ...]:
    pieces = tuple(pieces)
    for p in pieces:
        if not isinstance(p, Disc | Box):
            raise TypeError(f"{name} must hold envs.Disc or envs.Box pieces, got {p!r}")
    return pieces


class IslandsBridges(gym.Env[NDArray[np.float32], NDArray[np.float32]]):
    """Walk from a start to a goal on islands joined by narrow bridges without falling off.

    The safe region is the union of ``islands`` and ``bridges`` (convex ``Disc`` and
    ``Box`` pieces of ``envs.geometry``). Its signed distance ``M(s)`` (positive inside,
    ``safe_distance``) decides failure. Start and goal are drawn on the islands.

    ## Action Space

    ``Box(-1, 1, (2,), float32)``: a step; the position moves by ``max_step * clip(a, -1, 1)``.

    | Num | Action                  | Min | Max | Unit                    |
    |-----|-------------------------|-----|-----|-------------------------|
    | 0   | step along x, ``dx``    | -1  | 1   | ``max_step`` map units  |
    | 1   | step along y, ``dy``    | -1  | 1   | ``max_step`` map units  |

    The dynamics are exact and known: ``predict(s, a) = s + action_scale * clip(a, -1, 1)``
    with ``action_scale = max_step``.

    ## Observation Space

    ``Box(float32, (4,))``, bounded by the map's bounding box grown by ``max_step`` (the
    farthest a step can leave the map):

    | Num | Observation          | Unit      |
    |-----|----------------------|-----------|
    | 0   | agent ``x``          | map units |
    | 1   | agent ``y``          | map units |
    | 2   | goal ``x_goal``      | map units |
    | 3   | goal ``y_goal``      | map units |

    ## Starting State

    The goal, then the start, are drawn area-uniformly on the islands (an island is picked
    with probability proportional to its area, then a point uniformly in it); by default
    (``different_islands=True``) on different islands, and never within ``goal_eps`` of each
    other. ``reset(options={"start": (x, y), "goal": (x, y)})`` sets either explicitly (each
    must lie in the safe region).

    ## Rewards

    With ``d = ||s_{t+1} - goal||``:

    - ``reward="dense"``: ``-d``.
    - ``reward="sparse"``: ``1.0`` on success (``d <= goal_eps`` and the new state safe),
      else ``0.0``.

    There is no failure penalty: the episode ends and no more reward can be collected.
    ``info["reward_goal"]`` carries the (only) reward term; the reward equals it.

    ## Episode End

    - Termination (failure): ``M(s_{t+1}) < 0``, the agent stepped off the safe region
      (``info["failure"]``).
    - Termination (success): ``d <= goal_eps`` with ``M(s_{t+1}) >= 0``
      (``info["is_success"]``).
    - Truncation: 200 steps, by the ``TimeLimit`` of ``gym.make("ihm/IslandsBridges-v0")``
      and ``gym.make("ihm/IslandsBridgesRing-v0")``.

    Every step's ``info`` has ``is_success``, ``failure``, ``distance_to_edge`` (``M(s_{t+1})``),
    ``distance_to_goal`` (``d``) and ``reward_goal``; reset's ``info`` has ``distance_to_edge``,
    ``distance_to_goal``, ``start_island`` and ``goal_island`` (indices into ``islands``).

    ## Arguments

    - ``reward``: ``"dense"`` (default) or ``"sparse"``.
    - ``max_step``: step length per unit action component (default 0.1 map units), > 0.
    - ``goal_eps``: radius of the goal region (default 0.1), > 0.
    - ``islands``: sequence of ``Disc``/``Box``; ``None`` is the default (v0) map's
      ``DEFAULT_ISLANDS``.
    - ``bridges``: sequence of ``Disc``/``Box``; ``None`` is ``DEFAULT_BRIDGES`` when
      ``islands`` is ``None`` as well, else no bridges.
    - ``different_islands``: draw start and goal on different islands (default ``True``;
      needs at least two islands).
    - ``render_mode``: ``None`` or ``"rgb_array"`` (a top view, red agent, blue goal).

    ## Default Map

    Each map has its own Gymnasium id (``draw_map`` draws either):

    - ``ihm/IslandsBridgesRing-v0``, the ring (``RING_ISLANDS``, ``RING_BRIDGES``): four islands
      joined by four bridges 0.1 wide, I0 ``Disc((0.4, 0.4), 0.3)``, I1
      ``Box((1.3, 0.15), (1.9, 0.65))``, I2 ``Disc((1.6, 1.55), 0.3)``, I3
      ``Box((0.1, 1.2), (0.7, 1.8))``; bridges B0 ``Box((0.6, 0.35), (1.35, 0.45))`` (I0-I1),
      B1 ``Box((1.55, 0.6), (1.65, 1.3))`` (I1-I2), B2 ``Box((0.35, 0.65), (0.45, 1.25))``
      (I0-I3), B3 ``Box((0.65, 1.5), (1.35, 1.6))`` (I3-I2).
    - ``ihm/IslandsBridges-v0``, the five-island map (``SPUR_ISLANDS``, ``SPUR_BRIDGES``; also
      ``DEFAULT_ISLANDS``, ``DEFAULT_BRIDGES``, what ``IslandsBridges()`` builds): the ring
      plus the dead-end island I4 ``Disc((1.0, 1.0), 0.2)`` in the middle, reached only by the
      spur B4 ``Box((0.95, 0.35), (1.05, 0.85))`` that leaves B0 at a T-junction.

    ## Version History

    - ``ihm/IslandsBridges-v0``: initial version (thesis chapter 7), the five-island map with
      the dead-end island I4 reached by the spur B4 (``SPUR_ISLANDS``, ``SPUR_BRIDGES``), the
      first shipped map.
    - ``ihm/IslandsBridgesRing-v0``: the four-island ring (``RING_ISLANDS``,
      ``RING_BRIDGES``), a map of its own (not a newer version of v0, so it has its own name
      rather than ``-v1``, which Gymnasium would treat as superseding v0); dynamics, rewards
      and the 200-step limit as in ``ihm/IslandsBridges-v0``. A change to either map will be
      a new version of that id.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(
        self,
        reward: str = "dense",
        max_step: float = 0.1,
        goal_eps: float = 0.1,
        islands: Sequence[Piece] | None = None,
        bridges: Sequence[Piece] | None = None,
        different_islands: bool = True,
        render_mode: str | None = None,
    ) -> None:
        if reward not in ("dense", "sparse"):
            raise ValueError(f"reward must be 'dense' or 'sparse', got {reward!r}")
        if not (math.isfinite(max_step) and max_step > 0):
            raise ValueError(f"max_step must be finite and > 0, got {max_step!r}")
        if not (math.isfinite(goal_eps) and goal_eps > 0):
            raise ValueError(f"goal_eps must be finite and > 0, got {goal_eps!r}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode must be None or one of {self.metadata['render_modes']}, "
                f"got {render_mode!r}"
            )
        if islands is None:
            islands = DEFAULT_ISLANDS
            bridges = DEFAULT_BRIDGES if bridges is None else bridges
        self.islands = _check_pieces("islands", islands)
        self.bridges = _check_pieces("bridges", () if bridges is None else bridges)
        if not self.islands:
            raise ValueError("the map is empty: islands must hold at least one Disc or Box")
        if different_islands and len(self.islands) < 2:
            raise ValueError(
                "different_islands=True needs at least two islands, "
                f"got {len(self.islands)}; pass different_islands=False"
            )

        self.reward_mode = reward
        self.max_step = float(max_step)
        self.goal_eps = float(goal_eps)
        self.different_islands = bool(different_islands)
        self.render_mode = render_mode

        #: The safe region's convex pieces (islands, then bridges), used by the smart shield.
        self.safe_pieces: tuple[Piece, ...] = self.islands + self.bridges
        #: ``predict(s, a) = s + action_scale * clip(a, -1, 1)``.
        self.action_scale = self.max_step
        areas = np.array([_area(p) for p in self.islands])
        self._island_p = areas / areas.sum()
        # cumulative island probabilities, with each island excluded in turn (None: none), built
        # exactly as Generator.choice(n, p=p) builds its cdf, so that _choose_island draws the
        # same island from the same uniform number (tested against Generator.choice)
        self._island_cdf: dict[int | None, list[float]] = {}
        for exclude in (None, *range(len(self.islands))):
            p = self._island_p
            if exclude is not None:
                p = p.copy()
                p[exclude] = 0.0
                p /= p.sum()
            cdf = p.cumsum()
            cdf /= cdf[-1]
            self._island_cdf[exclude] = cdf.tolist()

        lo = np.min([p.bounds()[0] for p in self.safe_pieces], axis=0)
        hi = np.max([p.bounds()[1] for p in self.safe_pieces], axis=0)
        #: The map's bounding box ``(lo, hi)``.
        self.map_bounds = (lo, hi)
        obs_lo = np.concatenate([lo - self.max_step, lo]).astype(np.float32)
        obs_hi = np.concatenate([hi + self.max_step, hi]).astype(np.float32)
        self.observation_space = spaces.Box(obs_lo, obs_hi, dtype=np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)

        #: Current position (2,), float64; set by ``reset``.
        self.state = np.zeros(2)
        #: Goal position (2,), float64; set by ``reset``.
        self.goal = np.zeros(2)
        self._has_reset = False
        self._background: NDArray[np.uint8] | None = None

    # ---- model used by the shields ----------------------------------------------------

    def predict(self, state: ArrayLike, action: ArrayLike) -> NDArray[np.float64]:
        """Next state after ``action`` from ``state``: ``state + action_scale * clip(a, -1, 1)``."""
        a = np.clip(np.asarray(action, dtype=float), -1.0, 1.0)
        return np.asarray(state, dtype=float) + self.action_scale * a

    def safe_distance(self, state: ArrayLike) -> float:
        """Thesis ``M(s)``: signed distance to the edge of the safe region, >= 0 is safe."""
        return float(signed_distance(self.safe_pieces, np.asarray(state, dtype=float)))

    def _depth(self, x: float, y: float) -> float:
        """``safe_distance((x, y))`` in floats: the same value to the last bit, no arrays."""
        return point_signed_distance(self.safe_pieces, x, y)

    # ---- Gymnasium API ----------------------------------------------------------------

    def _sample_on_island(self, i: int) -> NDArray[np.float64]:
        piece = self.islands[i]
        rng = self.np_random
        if isinstance(piece, Disc):
            r = piece.radius * math.sqrt(rng.random())
            t = 2.0 * math.pi * rng.random()
            return np.asarray(piece.center, dtype=float) + r * np.array([math.cos(t), math.sin(t)])
        lo, hi = piece.bounds()
        return lo + rng.random(2) * (hi - lo)

    def _choose_island(self, exclude: int | None) -> int:
        """``np_random.choice(len(islands), p=p)`` (``p`` with ``exclude`` zeroed and
        renormalised): one uniform number looked up in the same cdf, the same draw."""
        cdf = self._island_cdf[exclude]
        return bisect.bisect_right(cdf, self.np_random.random())

    def _sample_point(self, exclude: int | None = None) -> tuple[int, NDArray[np.float64]]:
        for _ in range(1000):
            i = self._choose_island(exclude)
            x = self._sample_on_island(i)
            if self._depth(float(x[0]), float(x[1])) >= 0:  # guards round-off on a disc's rim
                return i, x
        raise RuntimeError("could not sample a point in the safe region")  # pragma: no cover

    def _island_of(self, x: NDArray[np.float64]) -> int:
        """Index of the island that contains ``x`` (deepest; the first of equals), -1 if on
        no island."""
        px, py = float(x[0]), float(x[1])
        depth = [point_depth(p, px, py) for p in self.islands]
        i = max(range(len(depth)), key=depth.__getitem__)
        return i if depth[i] >= 0 else -1

    def _given_point(self, options: dict[str, Any], key: str) -> NDArray[np.float64] | None:
        if key not in options or options[key] is None:
            return None
        x = np.asarray(options[key], dtype=float)
        if x.shape != (2,) or not np.all(np.isfinite(x)):
            raise ValueError(f"options[{key!r}] must be a finite (x, y), got {options[key]!r}")
        if self.safe_distance(x) < 0:
            raise ValueError(f"options[{key!r}] = {x.tolist()} is outside the safe region")
        return x

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        super().reset(seed=seed)
        options = options or {}
        start = self._given_point(options, "start")
        goal = self._given_point(options, "goal")
        if goal is None:
            _, goal = self._sample_point()
        goal_island = self._island_of(goal)
        if start is None:
            exclude = goal_island if self.different_islands and goal_island >= 0 else None
            for _ in range(1000):
                _, start = self._sample_point(exclude)
                if _dist(start[0], start[1], goal[0], goal[1]) > self.goal_eps:
                    break
            else:  # pragma: no cover - only on maps with tiny islands
                raise RuntimeError("could not sample a start farther than goal_eps from the goal")
        self.state = np.array(start, dtype=float)
        self.goal = np.array(goal, dtype=float)
        self._has_reset = True
        sx, sy = float(self.state[0]), float(self.state[1])
        info = {
            "distance_to_edge": self._depth(sx, sy),
            "distance_to_goal": _dist(sx, sy, float(self.goal[0]), float(self.goal[1])),
            "start_island": self._island_of(self.state),
            "goal_island": goal_island,
        }
        return self._obs(), info

    def step(
        self, action: ArrayLike
    ) -> tuple[NDArray[np.float32], SupportsFloat, bool, bool, dict[str, Any]]:
        if not self._has_reset:
            raise RuntimeError("call reset() before step()")
        a = np.asarray(action, dtype=float)
        if a.shape != (2,):
            raise ValueError(f"action must be a finite array of shape (2,), got {action!r}")
        ax, ay = float(a[0]), float(a[1])
        if not (math.isfinite(ax) and math.isfinite(ay)):
            raise ValueError(f"action must be a finite array of shape (2,), got {action!r}")
        # predict(), in floats: s + k * clip(a, -1, 1), the same IEEE operations
        k = self.action_scale
        x = float(self.state[0]) + k * min(max(ax, -1.0), 1.0)
        y = float(self.state[1]) + k * min(max(ay, -1.0), 1.0)
        self.state = np.array([x, y])
        edge = self._depth(x, y)
        gx, gy = float(self.goal[0]), float(self.goal[1])
        dist = _dist(x, y, gx, gy)
        failure = edge < 0
        success = (not failure) and dist <= self.goal_eps
        if self.reward_mode == "dense":
            reward = -dist
        else:
            reward = 1.0 if success else 0.0
        info = {
            "is_success": success,
            "failure": failure,
            "distance_to_edge": edge,
            "distance_to_goal": dist,
            "reward_goal": reward,
        }
        obs = np.array([x, y, gx, gy], dtype=np.float32)
        return obs, reward, failure or success, False, info

    def _obs(self) -> NDArray[np.float32]:
        return np.concatenate([self.state, self.goal]).astype(np.float32)

    # ---- rendering --------------------------------------------------------------------

    def _frame(self, px_per_unit: float = 200.0, margin: float = 0.1) -> tuple[Any, ...]:
        lo, hi = self.map_bounds
        lo, hi = lo - margin, hi + margin
        w, h = (int(math.ceil(v)) for v in (hi - lo) * px_per_unit)
        return lo, hi, w, h, px_per_unit

    def render(self) -> NDArray[np.uint8] | None:
        """Top view as an ``(H, W, 3)`` uint8 image: land, shore line, goal disc, agent."""
        if self.render_mode is None:
            gym.logger.warn("render() called with render_mode=None; pass render_mode='rgb_array'")
            return None
        lo, hi, w, h, ppu = self._frame()
        xs = lo[0] + (np.arange(w) + 0.5) / ppu
        ys = hi[1] - (np.arange(h) + 0.5) / ppu  # row 0 is the top (largest y)
        grid = np.stack(np.meshgrid(xs, ys), axis=-1)
        if self._background is None:
            m = signed_distance(self.safe_pieces, grid)
            img = np.where((m >= 0)[..., None], _LAND, _SEA).astype(np.uint8)
            img[np.abs(m) <= 1.0 / ppu] = _SHORE
            self._background = img
        img = self._background.copy()
        goal_r = max(self.goal_eps, 3.0 / ppu)
        img[np.linalg.norm(grid - self.goal, axis=-1) <= goal_r] = _GOAL
        img[np.linalg.norm(grid - self.state, axis=-1) <= 6.0 / ppu] = _AGENT
        return img


def _map_title(islands: tuple[Piece, ...], bridges: tuple[Piece, ...]) -> str:
    """Plot title naming the registered id whose map this is, else "custom map"."""
    if (islands, bridges) == (SPUR_ISLANDS, SPUR_BRIDGES):
        return "IslandsBridges-v0 map (five islands; bridges 0.1 wide)"
    if (islands, bridges) == (RING_ISLANDS, RING_BRIDGES):
        return "IslandsBridgesRing-v0 map (four-island ring; bridges 0.1 wide)"
    return f"custom map ({len(islands)} islands, {len(bridges)} bridges)"


def draw_map(
    path: str | Path,
    islands: Sequence[Piece] | None = None,
    bridges: Sequence[Piece] | None = None,
    start: ArrayLike | None = (0.35, 0.3),
    goal: ArrayLike | None = (1.65, 1.65),
    title: str | None = None,
) -> Path:
    """Draw a map (default: the v0 map, ``DEFAULT_ISLANDS``) with labelled pieces to a PNG.

    Pass ``RING_ISLANDS``, ``RING_BRIDGES`` for the ring. ``start`` (red) and ``goal``
    (blue) mark an example task; ``None`` leaves them out. ``title`` defaults to the id of the
    registered map the pieces are (``IslandsBridges-v0`` or ``IslandsBridgesRing-v0``), else
    "custom map".
    Returns the path written. Used for ``docs/islands_map.png``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle, Rectangle

    env = IslandsBridges(islands=islands, bridges=bridges, different_islands=False)
    fig, ax = plt.subplots(figsize=(5.5, 5.5), dpi=120)
    ax.set_facecolor(_SEA / 255)
    for kind, pieces in (("I", env.islands), ("B", env.bridges)):
        for k, p in enumerate(pieces):
            if isinstance(p, Disc):
                patch = Circle(p.center, p.radius)
                mid = np.asarray(p.center)
            else:
                lo, hi = p.bounds()
                patch = Rectangle(tuple(lo), *(hi - lo))
                mid = (lo + hi) / 2
            patch.set(facecolor=_LAND / 255, edgecolor=_SHORE / 255, linewidth=1.0, zorder=1)
            ax.add_patch(patch)
            size = 11 if kind == "I" else 8
            ax.annotate(f"{kind}{k}", mid, ha="center", va="center", fontsize=size, zorder=3)
    if goal is not None:
        ax.add_patch(Circle(tuple(np.asarray(goal, float)), env.goal_eps, color=_GOAL / 255))
        ax.plot([], [], "o", color=_GOAL / 255, label=f"goal (radius goal_eps={env.goal_eps})")
    if start is not None:
        ax.plot(*np.asarray(start, float), "o", color=_AGENT / 255, label="agent", zorder=4)
    lo, hi = env.map_bounds
    ax.set_xlim(lo[0] - 0.1, hi[0] + 0.1)
    ax.set_ylim(lo[1] - 0.1, hi[1] + 0.1)
    ax.set_aspect("equal")
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.grid(True, alpha=0.3)
    ax.set_title(_map_title(env.islands, env.bridges) if title is None else title)
    if start is not None or goal is not None:
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=2, fontsize=8)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path
