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
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from envs.four_finger import (
    GRIPS,
    FourFingerError,
    FourFingerRotate,
    PhysicsSample,
    Randomization,
    corners,
)
from shields import make_shield
from stability.cli import ArgumentParser
from stability.io import write_csv
from train.evaluation import RotationEpisode, run_episodes
from train.policy import SHIPPED, load_policy
from train.rotation import MAX_DROP_RATE, TARGET_SPEED
from train.runfiles import PolicyError, check_policy_dir
from train.stats import wilson_interval

__all__ = [
    "csv_path",
    "evaluate_heldout",
    "held_grasps",
    "main",
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
    physics: PhysicsSample | None = None,
    n_envs: int = 10,
    seed: int = 0,
    screen: bool = False,
    shield: str = "none",
) -> dict[str, Any]:
    """``episodes`` deterministic episodes from test grasps ``0 .. episodes - 1`` (at most
    :data:`TEST_GRASPS`) under ``physics`` (nominal: ``None``); :func:`summarize` of them
    plus ``grasps`` (the test-grasp index of each episode, in the order they ended) and
    ``dropped_grasps`` (the indices of those that dropped, sorted).

    ``act`` maps a batch of observations to a batch of actions; ``seed`` seeds the envs'
    sensor noise. ``screen``: start only from test grasps that hold for ``seconds`` with
    zero actions under ``physics`` (:func:`held_grasps`; module doc), the first ``episodes``
    of them; ``unheld_starts`` counts the test grasps skipped on the way (fewer episodes run
    when fewer than ``episodes`` of the 100 hold). ``shield``: every env inside that shield
    (:func:`shields.make_shield`); the result then adds ``interventions_per_step`` and the
    shield's wall time per step, ``shield_ms_median`` and ``shield_ms_p95`` [ms]."""
    if not 1 <= episodes <= TEST_GRASPS:
        raise ValueError(f"episodes must be in [1, {TEST_GRASPS}], got {episodes}")
    kw = {**env_kwargs, "grasps": "test", "n_grasps": TEST_GRASPS, "physics": physics}
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
    steps = int(round(seconds / envs[0].unwrapped.dt))
    eps = run_episodes(
        envs,
        n,
        act,
        _Recorder,
        reset_options=lambda i, j: {"grasp": grasps[int(first[i] + j)]},
        max_steps=steps,
    )
    for env in envs:
        env.close()
    res = {
        **summarize(eps),
        "grasps": [e["grasp"] for e in eps],
        "dropped_grasps": sorted(e["grasp"] for e in eps if e["dropped"]),
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


def csv_path(out: Path, stem: str, range_scale: float = 1.0) -> Path:
    """Where ``--corners`` (``stem`` "robustness") or ``--factors`` ("factors") write their
    rows: ``{stem}.csv`` for the full ranges, ``{stem}_xS.csv`` for the ranges scaled by
    ``S = range_scale``."""
    return out / (f"{stem}.csv" if range_scale == 1.0 else f"{stem}_x{range_scale:g}.csv")


def still(obs: np.ndarray) -> np.ndarray:
    """The hand held still: zero actions for a batch of observations (``--still``)."""
    return np.zeros((len(obs), 12), dtype=np.float32)


def _load(policy_dir: Path, grip: str | None, hold_still: bool) -> tuple[Callable, dict]:
    act, kw = load_policy(Path(policy_dir))
    return (still if hold_still else act), (kw if grip is None else {**kw, "grip": grip})


def _corner_job(args: tuple[str, PhysicsSample, int, float, bool, str | None, bool]) -> dict:
    policy_dir, physics, episodes, seconds, screen, grip, hold_still = args
    import torch

    torch.set_num_threads(1)
    act, kw = _load(Path(policy_dir), grip, hold_still)
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
) -> list[dict[str, Any]]:
    """:func:`evaluate_heldout` at every corner of ``randomization`` (default: the env's
    :class:`Randomization`; ``single``: at each of its :func:`factors` instead), ``episodes``
    per case, ``workers`` processes; ``screen``: also from screened start grasps
    (``screened_*`` and ``unheld_starts`` columns; module doc); ``grip``: start grasps of
    that grip instead of the policy's own (:data:`envs.four_finger.GRIPS`); ``hold_still``:
    zero actions instead of the policy (:func:`still`: which start grasps hold by themselves)."""
    cases = corners(randomization) if not single else factors(randomization)
    jobs = [(str(policy_dir), c, episodes, seconds, screen, grip, hold_still) for c in cases]
    if workers <= 1:
        return [_corner_job(j) for j in jobs]
    with ProcessPoolExecutor(workers) as pool:
        return list(pool.map(_corner_job, jobs))


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    p = ArgumentParser(prog="python -m train.heldout", description=(__doc__ or "").split("\n\n")[0])
    p.add_argument("policy", nargs="?", default=str(SHIPPED), help="policy or run directory")
    p.add_argument("--episodes", type=int, default=100, help="held-out episodes (<= 100)")
    p.add_argument("--seconds", type=float, default=20.0, help="episode length [s]")
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
        "--still",
        action="store_true",
        help="zero actions instead of the policy (the policy's object and env settings): which "
        "start grasps hold with the hand still",
    )
    p.add_argument(
        "--range-scale",
        type=float,
        default=1.0,
        help="corners/factors of the ranges shrunk towards nominal by this factor in (0, 1] "
        "(Randomization.scaled); files robustness_xS.csv, factors_xS.csv",
    )
    p.add_argument("--out", default=None, help="directory for the outputs (default: policy)")
    a = p.parse_args(argv)
    try:
        ranges = Randomization().scaled(a.range_scale)
    except FourFingerError as e:
        p.error(f"--range-scale: {e}")
    if not 1 <= a.episodes <= TEST_GRASPS or a.corner_episodes < 1 or a.seconds <= 0:
        p.error(f"--episodes must be in [1, {TEST_GRASPS}], --corner-episodes >= 1, --seconds > 0")
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
    act, kw = _load(policy, a.grip, a.still)
    res = evaluate_heldout(act, kw, a.episodes, a.seconds)
    (out / "eval_heldout.json").write_text(json.dumps(res, indent=2) + "\n")
    print(_line(f"{policy} nominal", res))
    result: dict[str, Any] = {"nominal": res}
    for name, wanted, single in (("corners", a.corners, False), ("factors", a.factors, True)):
        if not wanted:
            continue
        rows = robustness(
            policy,
            a.corner_episodes,
            a.seconds,
            randomization=ranges,
            workers=a.workers,
            single=single,
            screen=a.screen,
            grip=a.grip,
            hold_still=a.still,
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
        write_csv(csv_path(out, stem, a.range_scale), csv_rows, cols)
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


if __name__ == "__main__":
    main()
