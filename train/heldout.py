"""Held-out evaluation of a rotation policy, nominal and at the corners of its randomised
physics: ``python -m train.heldout POLICY_DIR``.

Every episode starts from a grasp of the ``test`` set (:data:`envs.four_finger.GRASP_SETS`):
start grasps made by the same generator with a seed that no training run uses, episode
``i`` from test grasp ``i`` (so 100 episodes use 100 different grasps, none of them a
training grasp). The policy is deterministic; an episode lasts ``--seconds`` (20 s = 400
policy steps) or ends at a drop, whose time so far counts.

Measures per episode (:class:`train.evaluation.RotationEpisode`): the net turn (the
unwrapped z twist of the object's orientation relative to its start,
:func:`envs.four_finger.z_twist`) over the episode's time [rad/s], the summed per-step
rotation about +z (what the reward adds up) and the drop. Reported: the mean net speed with
a 95 % normal interval of the mean (``1.96 s / sqrt(n)``), the drop rate with its 95 %
Wilson interval (:func:`train.stats.wilson_interval`).

**Screened start grasps** (``--screen``, corners and factors only). A test grasp was made
and settled under nominal physics; under a corner's physics (half the friction, twice the
mass, weaker servos) some of them no longer hold even with the hand still. With
``--screen``, an episode starts only from a test grasp that holds under the case's physics
for the whole episode length with zero actions (the setpoints kept); the others are skipped
and counted (``unheld_starts``). The robustness table reports both: the policy's own drops
(screened) and the drops from every test grasp (unscreened).

Writes ``eval_heldout.json`` and, with ``--corners``, ``robustness.csv`` (one row per corner
of :func:`envs.four_finger.corners`: ``--corner-episodes`` episodes each; ``dropped_grasps``
names the test grasps whose episodes dropped, so a drop that recurs from one start grasp
at every corner shows), with ``--factors``
``factors.csv`` (one factor at a time, :func:`factors`) to ``--out`` (default: the policy
directory). ``--grip firm`` starts every episode from the firm-grip test grasps
(:data:`envs.four_finger.GRIPS`) whatever grip the policy was trained on; ``--still`` holds
the hand still (zero actions) instead of running the policy: the drops are then the start
grasps' own. ``--range-scale S`` (in (0, 1]) evaluates the corners and factors of the ranges
shrunk towards nominal (:meth:`envs.four_finger.Randomization.scaled`) and names the files
``robustness_xS.csv`` and ``factors_xS.csv``: a narrower stated range.

**Another object** (``--object NAME``, :data:`envs.four_finger.OBJECTS`): the policy runs on
that object instead of its ``config.json``'s (its other env settings kept), from that
object's test grasps; every output file carries the name (``eval_heldout_capsule.json``,
``robustness_capsule.csv``, ``robustness_x0.25_capsule.csv``, ``eval_playground_capsule.json``)
so that the policy's own stay. No shipped policy was trained on the held-out ``capsule`` and
``ellipsoid`` (:data:`envs.four_finger.HELDOUT_OBJECTS`).

**MuJoCo Playground's ranges** (``--ranges playground``, :data:`PLAYGROUND`): in place of the
nominal evaluation, the protocol of Playground's LEAP-hand cube rotate-z task, whose
published result (0.94 rad/s, 2.3 % drops) is printed beside this one: 128 episodes of 10 s,
each under its own physics drawn uniformly from the random stream ``(--seed, episode)``
(:meth:`PlaygroundPreset.draw`): the object's sliding friction coefficient 0.5-1.0 absolute
(Playground sets its fingertips' to that; every contact pair of the object here has the
nominal 1.0, :func:`nominal_friction`, so it is the env's friction scale x0.5-1.0), object
mass and each servo gain x0.8-1.2, torsional friction nominal, no latency, and Gaussian
joint-angle noise of std 0.029 rad (Playground adds uniform noise of +-0.05 rad; no contact
noise). Episode ``g`` starts from test grasp ``g``: the test set is enlarged to 128 grasps by
its own generator stream, whose first 100 are the usual ones; its sensor noise is seeded by
``seed + g``. Writes ``eval_playground.json`` (:func:`evaluate_playground`).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from envs.four_finger import (
    GRIPS,
    OBJECTS,
    TIMESTEP,
    FourFingerError,
    FourFingerRotate,
    ModelScaler,
    Physics,
    PhysicsSample,
    Randomization,
    centre,
    corners,
)
from ihm.hands.four_finger import NU
from shields import make_shield
from stability.cli import ArgumentParser
from stability.io import write_csv
from train.evaluation import RotationEpisode, run_episodes
from train.policy import SHIPPED, load_policy
from train.rotation import MAX_DROP_RATE, TARGET_SPEED
from train.runfiles import PolicyError, check_policy_dir
from train.stats import wilson_interval

__all__ = [
    "PLAYGROUND",
    "PlaygroundPreset",
    "csv_path",
    "evaluate_heldout",
    "evaluate_playground",
    "held_grasps",
    "main",
    "nominal_friction",
    "robustness",
    "still",
    "summarize",
]

TEST_GRASPS = 100  # size of the held-out start-grasp set


def summarize(episodes: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Means and 95 % intervals of a list of :class:`RotationEpisode` results."""
    v = np.array([e["speed_rad_s"] for e in episodes])
    n = len(v)
    drops = int(sum(e["dropped"] for e in episodes))
    half = 1.96 * float(v.std(ddof=1)) / math.sqrt(n) if n > 1 else math.nan
    lo, hi = wilson_interval(drops, n)
    return {
        "episodes": n,
        "speed_rad_s": float(v.mean()),
        "speed_ci95": [float(v.mean()) - half, float(v.mean()) + half],
        "speed_median_rad_s": float(np.median(v)),
        "speed_p10_rad_s": float(np.percentile(v, 10)),
        "summed_rad_s": float(np.mean([e["summed_rad_s"] for e in episodes])),
        "drops": drops,
        "drop_rate": drops / n,
        "drop_ci95": [lo, hi],
    }


def evaluate_heldout(
    act: Callable[[np.ndarray], np.ndarray],
    env_kwargs: dict[str, Any],
    episodes: int = 100,
    seconds: float = 20.0,
    physics: PhysicsSample | Sequence[PhysicsSample] | None = None,
    n_envs: int = 10,
    seed: int = 0,
    screen: bool = False,
    shield: str = "none",
    test_grasps: int = TEST_GRASPS,
) -> dict[str, Any]:
    """``episodes`` deterministic episodes from test grasps ``0 .. episodes - 1`` (at most
    ``test_grasps``, the size of the test set: :data:`TEST_GRASPS` = 100 or more; a larger set
    begins with the same 100 grasps) under ``physics`` (nominal: ``None``); :func:`summarize` of
    them plus ``grasps`` (the test-grasp index of each episode, in the order they ended),
    ``dropped_grasps`` (the indices of those that dropped, sorted) and ``drop_seconds`` (when
    each drop happened [s], sorted).

    ``act`` maps a batch of observations to a batch of actions; ``seed`` seeds the envs'
    sensor noise. ``physics`` may also give each episode its own: the episode from test grasp
    ``g`` runs under ``physics[g]`` (``episodes`` of them) with its sensor noise seeded by
    ``seed + g``, so that each episode is the same however the episodes fall to the envs.
    ``screen`` (one physics for all): start only from test grasps that hold for ``seconds``
    with zero actions under ``physics`` (:func:`held_grasps`; module doc), the first
    ``episodes`` of them; ``unheld_starts`` counts the test grasps skipped on the way (fewer
    episodes run when fewer than ``episodes`` of the 100 hold). ``shield``: every env inside
    that shield (:func:`shields.make_shield`); the result then adds
    ``interventions_per_step`` and the shield's wall time per step, ``shield_ms_median`` and
    ``shield_ms_p95`` [ms]."""
    if test_grasps < TEST_GRASPS:
        raise ValueError(f"test_grasps must be >= {TEST_GRASPS}, got {test_grasps}")
    if not 1 <= episodes <= test_grasps:
        raise ValueError(f"episodes must be in [1, {test_grasps}], got {episodes}")
    each = None if physics is None or isinstance(physics, PhysicsSample) else list(physics)
    if each is not None and (len(each) != episodes or screen):
        raise ValueError(
            f"per-episode physics: one per episode ({episodes}, got {len(each)}), without screen"
        )
    kw = {**env_kwargs, "grasps": "test", "n_grasps": test_grasps}
    kw["physics"] = None if each is not None else physics
    grasps, unheld = list(range(episodes)), 0
    if screen:
        grasps, unheld = held_grasps(kw, episodes, seconds)
        if not grasps:
            return {"episodes": 0, "unheld_starts": unheld, "grasps": [], "seconds": seconds}
    n = len(grasps)
    k = max(1, min(n_envs, n))
    envs = [make_shield(FourFingerRotate(**kw), shield) for _ in range(k)]
    for i, env in enumerate(envs):
        env.reset(seed=seed + i)
    first = np.cumsum([0] + [(n + i) // k for i in range(k)])
    dt = float(envs[0].unwrapped.dt)
    steps = int(round(seconds / dt))

    def start(i: int, j: int) -> dict[str, Any]:
        g = grasps[int(first[i] + j)]
        return {"grasp": g} if each is None else {"grasp": g, "physics": each[g]}

    eps = run_episodes(
        envs,
        n,
        act,
        _Recorder,
        reset_seed=None if each is None else lambda i, j: seed + grasps[int(first[i] + j)],
        reset_options=start,
        max_steps=steps,
    )
    for env in envs:
        env.close()
    res = {
        **summarize(eps),
        "grasps": [e["grasp"] for e in eps],
        "dropped_grasps": sorted(e["grasp"] for e in eps if e["dropped"]),
        "drop_seconds": sorted(round(e["steps"] * dt, 2) for e in eps if e["dropped"]),
        "seconds": seconds,
    }
    if shield != "none":
        times = np.concatenate([e["shield_seconds"] for e in eps]) * 1e3
        res["interventions_per_step"] = sum(e["interventions"] for e in eps) / len(times)
        res["shield_ms_median"], res["shield_ms_p95"] = np.percentile(times, [50, 95]).tolist()
    for e in eps:
        e.pop("shield_seconds")
    return {**res, "unheld_starts": unheld} if screen else res


def held_grasps(env_kwargs: dict[str, Any], wanted: int, seconds: float) -> tuple[list[int], int]:
    """The first ``wanted`` test grasps (in index order) that hold the object for ``seconds``
    with zero actions (every setpoint kept) in an env built with ``env_kwargs`` (its
    ``physics``), and how many were skipped before them because the object dropped."""
    env = FourFingerRotate(**env_kwargs)
    env.reset(seed=0)
    steps = int(round(seconds / env.dt))
    zero = np.zeros(env.action_space.shape, dtype=np.float32)
    held: list[int] = []
    unheld = 0
    for g in range(TEST_GRASPS):
        if len(held) == wanted:
            break
        env.reset(options={"grasp": g})
        for _ in range(steps):
            if env.step(zero)[2]:
                unheld += 1
                break
        else:
            held.append(g)
    env.close()
    return held, unheld


class _Recorder(RotationEpisode):
    """:class:`RotationEpisode` that also keeps the start grasp's index."""

    def __init__(self, env: Any, obs: Any = None, info: dict[str, Any] | None = None) -> None:
        super().__init__(env, obs, info)
        self.grasp = int((info or {}).get("grasp", -1))

    def result(self) -> dict[str, Any]:
        seconds = np.array(self.shield_seconds)  # the shield's wall time per step [s]
        return {**super().result(), "grasp": self.grasp, "shield_seconds": seconds}


def factors(r: Randomization | None = None) -> list[PhysicsSample]:
    """One factor of ``r`` at a time, each bound on its own, nominal otherwise: friction,
    torsional friction, mass and gain at each bound, one step of latency, the sensor noise
    (what ``--factors`` evaluates: which factor a corner's failure comes from)."""
    r = r or Randomization()
    out = [
        PhysicsSample(**{k: v})
        for k in ("friction", "torsional", "mass", "gain")
        for v in getattr(r, k)
    ]
    return [
        *out,
        PhysicsSample(latency=1),
        PhysicsSample(noise=(r.noise_joint, r.noise_pos, r.noise_force)),
    ]


def csv_path(out: Path, stem: str, range_scale: float = 1.0, obj: str | None = None) -> Path:
    """Where ``--corners`` (``stem`` "robustness") or ``--factors`` ("factors") write their
    rows: ``{stem}.csv`` for the full ranges, ``{stem}_xS.csv`` for the ranges scaled by
    ``S = range_scale``; with an object ``obj`` in place of the policy's own (``--object``)
    its name follows: ``{stem}_{obj}.csv``, ``{stem}_xS_{obj}.csv``."""
    scale = "" if range_scale == 1.0 else f"_x{range_scale:g}"
    return out / f"{stem}{scale}{_tag(obj)}.csv"


def _tag(obj: str | None) -> str:
    """The object's suffix of an output file name (``--object``): ``_capsule``, or nothing."""
    return "" if obj is None else f"_{obj}"


@dataclass(frozen=True)
class PlaygroundPreset:
    """MuJoCo Playground's LEAP-hand cube rotate-z evaluation in this env's terms
    (``--ranges playground``, module doc): ``episodes`` episodes of ``seconds``, each under its
    own physics drawn uniformly: the absolute sliding friction coefficient of the object's
    contacts from ``friction``, the object's mass (with its inertia) and each servo gain scaled
    by factors from ``mass`` and ``gain``; torsional friction nominal, no latency; Gaussian
    joint-position noise of std ``noise_joint`` [rad] (Playground's is uniform in +-0.05 rad,
    std 0.05 / sqrt(3)), no contact noise (Playground's hand senses no contacts).
    ``speed_rad_s`` [rad/s] and ``drop_rate``: Playground's published result, printed beside
    this env's."""

    episodes: int = 128
    seconds: float = 10.0
    friction: tuple[float, float] = (0.5, 1.0)
    mass: tuple[float, float] = (0.8, 1.2)
    gain: tuple[float, float] = (0.8, 1.2)
    noise_joint: float = 0.05 / math.sqrt(3.0)
    speed_rad_s: float = 0.94
    drop_rate: float = 0.023

    def draw(self, seed: int, episode: int, nominal: float = 1.0) -> PhysicsSample:
        """The physics of episode ``episode`` from the random stream ``(seed, episode)`` alone
        (the same sample however many episodes are drawn): friction scale = the drawn
        coefficient over ``nominal``, the object's nominal one (:func:`nominal_friction`);
        one gain factor per servo."""
        rng = np.random.default_rng([seed, episode])
        mu = float(rng.uniform(*self.friction))
        return PhysicsSample(
            friction=mu / nominal,
            torsional=1.0,
            mass=float(rng.uniform(*self.mass)),
            gain=tuple(float(g) for g in rng.uniform(*self.gain, NU)),
            latency=0,
            noise=(self.noise_joint, 0.0, 0.0),
        )


PLAYGROUND = PlaygroundPreset()


def nominal_friction(obj: str) -> float:
    """The nominal sliding friction coefficient of ``obj``'s contacts, ``pair_friction[:, 0]``
    of the env's explicit pairs of the object (with the 8 finger links, the palm and the catch
    plane): 1.0 for every object (the skin's and the objects' own). :class:`FourFingerError`
    if the pairs differ: the env scales them all by one factor, which then cannot give one
    absolute coefficient."""
    ph = Physics(obj, True, TIMESTEP)
    mu = ph.model.pair_friction[ModelScaler(ph.model, ph.data, ph.obj_body).obj_pairs, 0]
    if not np.all(mu == mu[0]):
        raise FourFingerError(
            f"{obj}: the object's contact pairs have different nominal friction "
            f"({sorted(set(mu.tolist()))}); an absolute friction range needs one"
        )
    return float(mu[0])


def evaluate_playground(
    act: Callable[[np.ndarray], np.ndarray],
    env_kwargs: dict[str, Any],
    preset: PlaygroundPreset = PLAYGROUND,
    episodes: int | None = None,
    seconds: float | None = None,
    seed: int = 0,
    n_envs: int = 10,
) -> dict[str, Any]:
    """:func:`evaluate_heldout` under ``preset`` (default ``preset.episodes`` x
    ``preset.seconds``): the episode from test grasp ``g`` under ``preset.draw(seed, g)``, its
    sensor noise seeded by ``seed + g``. With more than :data:`TEST_GRASPS` episodes the test
    set is enlarged to one grasp per episode (its first 100 are the usual test grasps).

    Returns :func:`summarize`'s measures (``speed_ci95``: 95 % normal interval of the mean
    speed; ``drop_ci95``: 95 % Wilson interval of the drop rate) with ``grasps`` and
    ``dropped_grasps``, plus ``seed``, ``preset`` (its fields), ``nominal_friction``,
    ``friction_scale`` (the friction range as scale factors of the env), ``physics`` (per
    test grasp: friction coefficient, mass scale, mean gain scale) and ``playground``
    (Playground's published speed [rad/s] and drop rate)."""
    n = preset.episodes if episodes is None else episodes
    secs = preset.seconds if seconds is None else seconds
    mu0 = nominal_friction(env_kwargs.get("object", "sphere"))
    each = [preset.draw(seed, g, mu0) for g in range(n)]
    res = evaluate_heldout(
        act, env_kwargs, n, secs, physics=each, n_envs=n_envs, seed=seed,
        test_grasps=max(n, TEST_GRASPS),
    )  # fmt: skip
    return {
        **res,
        "seed": seed,
        "preset": asdict(preset),
        "nominal_friction": mu0,
        "friction_scale": [preset.friction[0] / mu0, preset.friction[1] / mu0],
        "physics": [
            {
                "grasp": g,
                "friction": s.friction * mu0,
                "mass": s.mass,
                "gain": float(np.mean(s.gain)),
            }
            for g, s in enumerate(each)
        ],
        "playground": {"speed_rad_s": preset.speed_rad_s, "drop_rate": preset.drop_rate},
    }


def still(obs: np.ndarray) -> np.ndarray:
    """The hand held still: zero actions for a batch of observations (``--still``)."""
    return np.zeros((len(obs), 12), dtype=np.float32)


def _load(
    policy_dir: Path, grip: str | None, hold_still: bool, obj: str | None = None
) -> tuple[Callable, dict]:
    """The policy (or :func:`still`) and its env, with ``grip`` and ``obj`` in place of its own."""
    act, kw = load_policy(Path(policy_dir))
    kw = kw if grip is None else {**kw, "grip": grip}
    return (still if hold_still else act), (kw if obj is None else {**kw, "object": obj})


def _corner_job(
    args: tuple[str, PhysicsSample, int, float, bool, str | None, bool, str | None],
) -> dict:
    policy_dir, physics, episodes, seconds, screen, grip, hold_still, obj = args
    import torch

    torch.set_num_threads(1)
    act, kw = _load(Path(policy_dir), grip, hold_still, obj)
    res = evaluate_heldout(act, kw, episodes, seconds, physics=physics)
    res.pop("grasps")
    row = {"corner": physics.label(), **res}
    row["dropped_grasps"] = " ".join(map(str, res["dropped_grasps"]))  # test-grasp indices
    if screen:
        s = evaluate_heldout(act, kw, episodes, seconds, physics=physics, screen=True)
        row.update(
            screened_episodes=s["episodes"],
            screened_speed_rad_s=s.get("speed_rad_s", math.nan),
            screened_drops=s.get("drops", 0),
            screened_drop_rate=s.get("drop_rate", math.nan),
            unheld_starts=s["unheld_starts"],
        )
    return row


def robustness(
    policy_dir: Path,
    episodes: int = 20,
    seconds: float = 20.0,
    randomization: Randomization | None = None,
    workers: int = 2,
    single: bool = False,
    screen: bool = False,
    grip: str | None = None,
    hold_still: bool = False,
    obj: str | None = None,
) -> list[dict[str, Any]]:
    """:func:`evaluate_heldout` at every corner of ``randomization`` (default: the env's
    :class:`Randomization`; ``single``: at each of its :func:`factors` instead), ``episodes``
    per case, ``workers`` processes; ``screen``: also from screened start grasps
    (``screened_*`` and ``unheld_starts`` columns; module doc); ``grip``: start grasps of
    that grip instead of the policy's own (:data:`envs.four_finger.GRIPS`); ``hold_still``:
    zero actions instead of the policy (:func:`still`: which start grasps hold by themselves);
    ``obj``: that object in place of the policy's own (:data:`envs.four_finger.OBJECTS`)."""
    cases = corners(randomization) if not single else factors(randomization)
    jobs = [(str(policy_dir), c, episodes, seconds, screen, grip, hold_still, obj) for c in cases]
    if workers <= 1:
        return [_corner_job(j) for j in jobs]
    with ProcessPoolExecutor(workers) as pool:
        return list(pool.map(_corner_job, jobs))


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    p = ArgumentParser(prog="python -m train.heldout", description=(__doc__ or "").split("\n\n")[0])
    p.add_argument("policy", nargs="?", default=str(SHIPPED), help="policy or run directory")
    p.add_argument(
        "--episodes", type=int, default=None, help="held-out episodes (<= 100; playground: 128)"
    )
    p.add_argument("--seconds", type=float, default=None, help="episode length [s] (20; 10)")
    p.add_argument("--corners", action="store_true", help="also evaluate at the corners")
    p.add_argument("--factors", action="store_true", help="also one factor at a time")
    p.add_argument("--corner-episodes", type=int, default=20, help="episodes per corner")
    p.add_argument("--workers", type=int, default=2, help="processes for --corners")
    p.add_argument(
        "--screen",
        action="store_true",
        help="corners/factors also from start grasps that hold still under the case's physics",
    )
    p.add_argument(
        "--grip",
        choices=GRIPS,
        default=None,
        help="start grasps of this grip instead of the policy's own (nominal or firm)",
    )
    p.add_argument(
        "--object",
        choices=OBJECTS,
        default=None,
        help="evaluate on this object instead of the policy's own (its other env settings "
        "kept); the output files get its name: eval_heldout_OBJECT.json, ...",
    )
    p.add_argument(
        "--still",
        action="store_true",
        help="zero actions instead of the policy (the policy's env settings): which start "
        "grasps hold with the hand still",
    )
    p.add_argument(
        "--range-scale",
        type=float,
        default=1.0,
        help="corners/factors of the ranges shrunk towards nominal by this factor in (0, 1] "
        "(Randomization.scaled); files robustness_xS.csv, factors_xS.csv",
    )
    p.add_argument(
        "--ranges",
        choices=("env", "playground"),
        default="env",
        help="env: nominal physics (corners and factors of the env's ranges); playground: "
        "MuJoCo Playground's LEAP cube rotate-z evaluation instead (128 x 10 s, each episode "
        "its own physics; eval_playground.json)",
    )
    p.add_argument("--seed", type=int, default=0, help="playground: seed of the physics draws")
    p.add_argument(
        "--centre",
        action="store_true",
        help="also at the centre of the ranges (every scale at its range's centre, mass "
        "geometric, with latency and noise): eval_centre.json",
    )
    p.add_argument("--out", default=None, help="directory for the outputs (default: policy)")
    a = p.parse_args(argv)
    playground = a.ranges == "playground"
    if playground and (a.corners or a.factors or a.screen or a.range_scale != 1.0):
        p.error("--ranges playground does not combine with --corners, --factors, --screen or "
                "--range-scale")  # fmt: skip
    try:
        ranges = Randomization().scaled(a.range_scale)
    except FourFingerError as e:
        p.error(f"--range-scale: {e}")
    n_default, s_default = (
        (PLAYGROUND.episodes, PLAYGROUND.seconds) if playground else (TEST_GRASPS, 20.0)
    )
    episodes = a.episodes if a.episodes is not None else n_default
    seconds = a.seconds if a.seconds is not None else s_default
    top = math.inf if playground else TEST_GRASPS
    if not 1 <= episodes <= top or a.corner_episodes < 1 or seconds <= 0:
        p.error(f"--episodes must be in [1, {top}], --corner-episodes >= 1, --seconds > 0")
    if a.still and not a.out:
        p.error("--still needs --out (it would overwrite the policy's own evaluation files)")
    policy = Path(a.policy)
    try:
        check_policy_dir(policy)
    except PolicyError as e:
        p.error(str(e))
    out = Path(a.out) if a.out else policy
    out.mkdir(parents=True, exist_ok=True)
    os.environ.setdefault("MUJOCO_GL", "egl")
    import torch

    torch.set_num_threads(1)  # batches of 10 observations: more threads only spin
    act, kw = _load(policy, a.grip, a.still, a.object)
    tag = _tag(a.object)
    if playground:
        res = evaluate_playground(act, kw, episodes=episodes, seconds=seconds, seed=a.seed)
        (out / f"eval_playground{tag}.json").write_text(json.dumps(res, indent=2) + "\n")
        print(_playground_line(f"{policy} ({kw['object']})", res))
        return {"playground": res}
    res = evaluate_heldout(act, kw, episodes, seconds)
    (out / f"eval_heldout{tag}.json").write_text(json.dumps(res, indent=2) + "\n")
    print(_line(f"{policy} ({kw['object']}) nominal", res))
    result: dict[str, Any] = {"nominal": res}
    if a.centre:
        mid = centre(ranges)
        res = evaluate_heldout(act, kw, episodes, seconds, physics=mid)
        (out / f"eval_centre{tag}.json").write_text(json.dumps(res, indent=2) + "\n")
        print(_line(f"{policy} ({kw['object']}) {mid.label()}", res))
        result["centre"] = res
    for name, wanted, single in (("corners", a.corners, False), ("factors", a.factors, True)):
        if not wanted:
            continue
        rows = robustness(
            policy,
            a.corner_episodes,
            seconds,
            randomization=ranges,
            workers=a.workers,
            single=single,
            screen=a.screen,
            grip=a.grip,
            hold_still=a.still,
            obj=a.object,
        )
        cols = ["corner", "episodes", "speed_rad_s", "speed_median_rad_s", "drop_rate", "drops"]
        cols += ["dropped_grasps"]
        if a.screen:
            cols += [
                "screened_episodes",
                "screened_speed_rad_s",
                "screened_drop_rate",
                "screened_drops",
                "unheld_starts",
            ]
        csv_rows = [
            {k: round(v, 4) if isinstance(v, float) else v for k, v in r.items() if k in cols}
            for r in rows
        ]
        stem = "robustness" if name == "corners" else "factors"
        write_csv(csv_path(out, stem, a.range_scale, a.object), csv_rows, cols)
        for r in rows:
            print(_line(r["corner"], r))
            if a.screen:
                print(
                    f"  screened: {r['screened_episodes']} episodes, net "
                    f"{r['screened_speed_rad_s']:.3f} rad/s, drops {r['screened_drops']} "
                    f"({r['unheld_starts']} start grasps did not hold still)"
                )
        if name == "corners":
            target = f">= {TARGET_SPEED} rad/s and <= {MAX_DROP_RATE * 100:g} % drops"
            for pre in ("", "screened_") if a.screen else ("",):
                ok = all(
                    r[pre + "speed_rad_s"] >= TARGET_SPEED and r[pre + "drop_rate"] <= MAX_DROP_RATE
                    for r in rows
                )
                print(f"every corner {target}{' (screened)' if pre else ''}: {ok}")
        result[name] = rows
    return result


def _line(name: str, r: dict[str, Any]) -> str:
    return (
        f"{name}: {r['episodes']} x {r['seconds']:g} s, net {r['speed_rad_s']:.3f} rad/s "
        f"(summed {r['summed_rad_s']:.3f}), drops {r['drops']}/{r['episodes']}"
    )


def _playground_line(name: str, r: dict[str, Any]) -> str:
    """The preset's result with its intervals, beside Playground's published one."""
    (slo, shi), (dlo, dhi), pg = r["speed_ci95"], r["drop_ci95"], r["playground"]
    return (
        f"{name} under Playground's ranges: {r['episodes']} x {r['seconds']:g} s, net "
        f"{r['speed_rad_s']:.3f} rad/s (95 % CI {slo:.3f}-{shi:.3f}), drops "
        f"{r['drops']}/{r['episodes']} = {100 * r['drop_rate']:.1f} % (Wilson 95 % CI "
        f"{100 * dlo:.1f}-{100 * dhi:.1f} %)\n"
        f"Playground, LEAP hand turning its cube (published): {pg['speed_rad_s']:g} rad/s, "
        f"{100 * pg['drop_rate']:g} % drops"
    )


if __name__ == "__main__":
    main()
