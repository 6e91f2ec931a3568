"""Throughput of the four-finger rotation env: ``python -m envs.bench``.

Env steps per second for one process (physics + observation + reward, random
actions in [-1, 1]^12 from the cached start grasps: the training distribution),
from a baseline (row 1) to the shipped env, one change at a time:

1. ``landed``: the baseline: 1 ms x 50 substeps, Newton, noslip
   pass (20 iterations), impratio 1, palm and floor without collision, no
   finger-finger contacts, observation through ``ihm.grasp_from_mujoco``;
2. ``+ honest friction``: noslip off, impratio 100 (the grasp holds without noslip);
3. ``+ collisions``: palm, catch plane and finger-finger contacts on (what the task needs);
4. ``+ 2 ms x 25``: the timestep doubled (solref 0.01 s is still 5 timesteps);
5. ``+ PGS``: the same contact problem solved by PGS instead of Newton;
6. ``+ fast observation``: the env's own contact path;
7. ``+ torsional friction``: ``condim`` 4 (what the task needs: without it a sphere pinched
   between two antipodal point contacts spins freely). ``grasp_from_mujoco``
   refuses ``condim`` 4, so this comes after the observation row;
8. ``+ solver tolerance 1e-4``: PGS stops at 1e-4 instead of MuJoCo's 1e-8 (what the policy
   sees does not change: ``python -m train.bench fidelity``);
9. ``+ explicit pairs``: the contacts the scene allows as explicit ``<pair>``s (no
   broadphase): the same physics bit for bit (= the shipped env);
10. ``+ 2.5 ms x 20 (not shipped)``: the timestep 2.5 ms (solref 0.01 s is 4 timesteps): what
   a further cut of the substeps would buy, and what it changes.

Each row is the median over ``--repeats`` runs of ``--steps`` env steps (the rows take
turns), with its ratio to row 1 measured in the same run. The fidelity columns compare, on a
scripted turn (abduction setpoints +0.05 rad for 6 steps, then 6 steps of zero
action) from 8 cached grasps, the object's yaw and position at the end with
those of row 2's physics (median over the grasps).

The policy-based benchmarks are under ``train`` (they load a trained policy or train one,
and nothing below ``train`` imports it): PPO training
throughput is ``python -m train.bench training`` (four_finger_training.csv), the fidelity
table ``python -m train.bench fidelity`` (four_finger_fidelity.csv), the timestep transfer
``python -m train.bench transfer`` (four_finger_transfer.csv); ``--train``, ``--fidelity``
and ``--transfer`` print those commands.

Writes ``--out``/four_finger_env.csv and four_finger_env.png.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import mujoco
import numpy as np

from envs.four_finger import (
    FRAME_SKIP,
    TIMESTEP,
    FourFingerRotate,
    Physics,
    grasp_cache,
)
from ihm.contacts import grasp_from_mujoco
from ihm.hands import four_finger as ff
from stability import GraspError
from stability.cli import ArgumentParser
from stability.io import write_csv

THESIS_STEPS_PER_S = 15_360_000 / (9 * 3600)  # 474: thesis sec. 7.1.2, 15.36M steps in ~9 h


def _slow_observe(env: FourFingerRotate) -> Callable[[], np.ndarray]:
    """The observation through ihm.grasp_from_mujoco (rows 1-5; the env's own path after)."""
    m, d = env.model, env.data

    def observe() -> np.ndarray:
        o = np.zeros(56, dtype=np.float32)
        o[:12] = d.qpos[:12]
        o[12:24] = d.ctrl
        try:
            g = grasp_from_mujoco(m, d)
        except GraspError:
            return o
        pts = g.points_world()
        feats = o[24:].reshape(8, 4)
        for k, geom in enumerate(g.hand_geoms):
            name = m.body(m.geom_bodyid[geom]).name
            if name in ff.BODY_NAMES:
                i = ff.BODY_NAMES.index(name)
                feats[i, :3] = pts[k]
                feats[i, 3] += g.forces[k, 0]
        return o

    return observe


def make(level: int) -> FourFingerRotate:
    """A fresh env with the settings of row ``level`` (1..10; ``SHIPPED`` is the shipped env)."""
    timestep, frame_skip = (0.0025, 20) if level >= 10 else (TIMESTEP, FRAME_SKIP)
    env = FourFingerRotate(torsional=level >= 7, timestep=timestep, frame_skip=frame_skip)
    if level <= 8:  # the scene's own contacts (broadphase)
        env.physics = Physics("sphere", True, timestep, torsional=level >= 7, explicit_pairs=False)
        env.model, env.data = env.physics.model, env.physics.data
    m = env.model
    if level <= 7:
        m.opt.tolerance = 1e-8  # MuJoCo's default
    if level <= 4:
        m.opt.solver = mujoco.mjtSolver.mjSOL_NEWTON
    if level <= 3:
        m.opt.timestep = 0.001
        env.sim = dataclasses.replace(env.sim, timestep=0.001, frame_skip=50)
    if level <= 2:
        for g in range(m.ngeom):
            if m.geom_contype[g] == 2:  # finger capsules: objects only (rows 1-2)
                m.geom_contype[g], m.geom_conaffinity[g] = 0, 1
            elif m.geom(g).name in ("palm", "floor"):
                m.geom_contype[g] = m.geom_conaffinity[g] = 0
    if level <= 1:
        m.opt.noslip_iterations = 20
        m.opt.impratio = 1.0
    if level <= 5:
        env.observe = _slow_observe(env)  # type: ignore[method-assign]
    return env


ROWS = (
    "landed",
    "+ honest friction",
    "+ collisions",
    "+ 2 ms x 25",
    "+ PGS",
    "+ fast observation",
    "+ torsional friction",
    "+ solver tolerance 1e-4",
    "+ explicit pairs (shipped)",
    "+ 2.5 ms x 20 (not shipped)",
)
SHIPPED = 9


def steps_per_second(levels: Sequence[int], steps: int, repeats: int, seed: int = 0) -> dict:
    """Env steps/s per row in ``levels`` (random actions, resets from the grasp cache); the
    rows take turns, repeat by repeat, so that the machine's slow phases hit all alike."""
    envs = {level: make(level) for level in levels}
    rng = np.random.default_rng(seed)
    out: dict[int, list[float]] = {level: [] for level in levels}
    for r in range(repeats):
        acts = rng.uniform(-1, 1, (steps, 12)).astype(np.float32)
        for level, env in envs.items():
            env.reset(seed=seed + r)
            t = time.perf_counter()
            for a in acts:
                if env.step(a)[2]:
                    env.reset()
            out[level].append(steps / (time.perf_counter() - t))
    return out


def scripted_turn(level: int, grasps: Sequence[int] = range(8)) -> np.ndarray:
    """Per start grasp: (yaw [rad], x, y, z [m]) of the object after the scripted turn, from
    the shipped env's cached grasps ``grasps`` (the same start states for every row)."""
    env = make(level)
    env.grasps = grasp_cache("sphere", True)
    act = np.zeros(12, dtype=np.float32)
    act[0::3] = 1.0
    res = []
    for i in grasps:
        env.reset(options={"grasp": i})
        for k in range(12):
            info = env.step(act if k < 6 else 0 * act)[4]
        res.append([info["rotation_angle"], *env.data.qpos[ff.NQ : ff.NQ + 3]])
    return np.array(res)


MOVED = {  # option: the train.bench command that runs that part
    "train": "python -m train.bench training",
    "fidelity": "python -m train.bench fidelity",
    "transfer": "python -m train.bench transfer",
    "train_rollouts": "python -m train.bench training --rollouts N",
}


def main(argv: Sequence[str] | None = None) -> list[dict[str, object]]:
    p = ArgumentParser(prog="python -m envs.bench", description=__doc__.split("\n\n")[0])
    p.add_argument("--steps", type=int, default=600, help="env steps per repeat")
    p.add_argument("--repeats", type=int, default=5, help="repeats per row (median reported)")
    p.add_argument("--out", default="bench_out", help="directory for the CSV and PNG")
    # the options of the parts train.bench runs: --no-X is accepted, --X exits naming the command
    p.add_argument("--env", action=argparse.BooleanOptionalAction, default=True,
                   help=argparse.SUPPRESS)  # fmt: skip
    for name in ("train", "fidelity", "transfer"):
        p.add_argument(f"--{name}", action=argparse.BooleanOptionalAction, default=False,
                       help=argparse.SUPPRESS)  # fmt: skip
    p.add_argument("--train-rollouts", type=int, default=None, help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    moved = [cmd for name, cmd in MOVED.items() if getattr(a, name) not in (False, None)]
    if moved:
        p.error(f"moved under train (run {'; '.join(moved)})")
    if not a.env:  # --no-env skips the env rows, the only ones this command runs
        p.error("--no-env leaves nothing to run here: the training and policy benchmarks are "
                "python -m train.bench training|fidelity|transfer")  # fmt: skip
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    rows: list[dict[str, object]] = []
    ref = scripted_turn(2)
    base = None
    rates = steps_per_second(range(1, len(ROWS) + 1), a.steps, a.repeats)
    for level, name in enumerate(ROWS, start=1):
        sps = rates[level]
        med = float(np.median(sps))
        base = base or med
        turn = scripted_turn(level)
        rows.append(
            {
                "config": name,
                "env_steps_per_s": round(med, 1),
                "min": round(min(sps), 1),
                "max": round(max(sps), 1),
                "ratio_to_landed": round(med / base, 2),
                "yaw_diff_rad": round(float(np.median(np.abs(turn[:, 0] - ref[:, 0]))), 4),
                "pos_diff_mm": round(
                    float(np.median(np.linalg.norm(turn[:, 1:] - ref[:, 1:], axis=1))) * 1e3, 3
                ),
                "turn_yaw_rad": round(float(np.median(turn[:, 0])), 4),
            }
        )
        r = rows[-1]
        print(
            f"{name:20s} {med:7.0f} env steps/s (x{r['ratio_to_landed']}), scripted turn: "
            f"yaw {r['turn_yaw_rad']:+.3f} rad, vs row 2: {r['yaw_diff_rad']:.4f} rad, "
            f"{r['pos_diff_mm']:.3f} mm"
        )
    thesis = round(THESIS_STEPS_PER_S)
    rows.append({"config": "thesis training (server)", "env_steps_per_s": thesis})
    write_csv(out / "four_finger_env.csv", rows)
    _plot(rows, out / "four_finger_env.png")
    print(f"wrote {out / 'four_finger_env.csv'} and {out / 'four_finger_env.png'}")
    return rows


def _plot(rows: list[dict[str, object]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = [str(r["config"]) for r in rows]
    vals = [float(r["env_steps_per_s"]) for r in rows]  # type: ignore[arg-type]
    colors = ["C0" if r["config"] in ROWS else "C1" for r in rows]
    fig, ax = plt.subplots(figsize=(10, 5))
    ax.barh(names[::-1], vals[::-1], color=colors[::-1])
    for y, v in enumerate(vals[::-1]):
        ax.text(v, y, f" {v:.0f}", va="center")
    ax.axvline(1500, color="gray", ls=":", lw=1)
    ax.set_xlabel("env steps per second (one process)")
    ax.set_xlim(0, max(vals) * 1.15 + 100)
    ax.set_title("Four-finger rotation env on this 2-core machine (dotted: 1,500 target)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
