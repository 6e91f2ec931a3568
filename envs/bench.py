"""Throughput of the four-finger rotation env and of PPO training on it: ``python -m envs.bench``.

Env steps per second for one process (physics + observation + reward, random
actions in [-1, 1]^12 from the cached start grasps: the training distribution),
from the landed model's settings to the shipped env, one change at a time:

1. ``landed``: the hand model as first landed: 1 ms x 50 substeps, Newton, noslip
   pass (20 iterations), impratio 1, palm and floor without collision, no
   finger-finger contacts, observation through ``ihm.grasp_from_mujoco``;
2. ``+ honest friction``: noslip off, impratio 100 (the grasp holds without noslip);
3. ``+ collisions``: palm, catch plane and finger-finger contacts on (what the task needs);
4. ``+ 2 ms x 25``: the timestep doubled (solref 0.01 s is still 5 timesteps);
5. ``+ PGS``: the same contact problem solved by PGS instead of Newton;
6. ``+ fast observation``: the env's own contact path;
7. ``+ torsional friction``: ``condim`` 4 (what the task needs: without it PPO learned to
   spin the sphere freely between two antipodal point contacts). ``grasp_from_mujoco``
   refuses ``condim`` 4, so this comes after the observation row;
8. ``+ solver tolerance 1e-4``: PGS stops at 1e-4 instead of MuJoCo's 1e-8 (what the policy
   sees does not change: :func:`timestep_fidelity`);
9. ``+ explicit pairs``: the contacts the scene allows as explicit ``<pair>``s (no
   broadphase): the same physics bit for bit (= the shipped env);
10. ``+ 2.5 ms x 20 (not shipped)``: the timestep 2.5 ms (solref 0.01 s is 4 timesteps): what
   a further cut of the substeps would buy, and what it changes.

Each row is the median over ``--repeats`` runs of ``--steps`` env steps (the rows take
turns), with its ratio to row 1 measured in the same run. The fidelity columns compare, on a
scripted turn (abduction setpoints +0.05 rad for 6 steps, then 6 steps of zero
action) from 8 cached grasps, the object's yaw and position at the end with
those of row 2's physics (median over the grasps).

``--train`` adds PPO training throughput (env steps/s including the updates) with
``python -m train.ppo``'s default settings (4 x 512 nets, 16 envs, 6,144-step
rollouts), the envs stepped in the training process, in 2 worker processes
(``train.vec.ChunkedVecEnv``), and in 2 worker processes with pipelined rollouts
(``train.pipeline.PipelinedPPO``, the default), beside the thesis' 474 env steps/s
(15.36M steps in about 9 h). The three setups take turns rollout by rollout in one
process (``--train-rollouts`` each); the ratio column is the median of the per-turn
ratios to the in-process setup.

``--fidelity`` adds what coarser physics would change in what the policy sees
(:func:`timestep_fidelity`: one policy step from the shipped policy's states against a
converged reference), written to four_finger_fidelity.csv.

``--transfer`` evaluates the shipped policy (trained at 2 ms) and one trained at 2.5 ms
(``policies/four_finger_sphere_2.5ms``, ``python -m train.ppo --timestep 0.0025``, same
seed and budget) under 1, 2 and 2.5 ms physics (:func:`timestep_transfer`), written to
four_finger_transfer.csv.

Writes ``--out``/four_finger_env.csv and four_finger_env.png.
"""

from __future__ import annotations

import argparse
import csv
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
    policy_step_outcomes,
    save_state,
)
from ihm.contacts import grasp_from_mujoco
from ihm.hands import four_finger as ff
from stability import GraspError

THESIS_STEPS_PER_S = 15_360_000 / (9 * 3600)  # 474: thesis sec. 7.1.2, 15.36M steps in ~9 h


def _slow_observe(env: FourFingerRotate) -> Callable[[], np.ndarray]:
    """The observation through ihm.grasp_from_mujoco (what was available before the env)."""
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
        env.frame_skip = 50
    if level <= 2:
        for g in range(m.ngeom):
            if m.geom_contype[g] == 2:  # finger capsules: objects only, as landed
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


FIDELITY = (  # label, timestep [s], substeps, solver, tolerance
    ("1 ms x 50, Newton converged", 0.001, 50, "newton", 1e-12),
    ("2 ms x 25, PGS 1e-8", 0.002, 25, "pgs", 1e-8),
    ("2 ms x 25, PGS 1e-6", 0.002, 25, "pgs", 1e-6),
    ("2 ms x 25, PGS 1e-4 (shipped)", 0.002, 25, "pgs", 1e-4),
    ("2 ms x 25, PGS 1e-3", 0.002, 25, "pgs", 1e-3),
    ("2.5 ms x 20, PGS 1e-4", 0.0025, 20, "pgs", 1e-4),
    ("3.125 ms x 16, PGS 1e-4", 0.003125, 16, "pgs", 1e-4),
)


def timestep_fidelity(episodes: int = 12, every: int = 4) -> list[dict[str, object]]:
    """What the policy sees under coarser physics: from states of the shipped policy's
    rollouts (every ``every``-th step of ``episodes`` episodes, with that step's action
    applied), one policy step (50 ms) per setting of :data:`FIDELITY`, compared with a
    converged reference (0.5 ms x 100, Newton to 1e-12): the reward (the object's yaw rate
    [rad/s]), the object's position [mm] and the observed link normal forces [N]
    (largest link error per state); median and 95th percentile over the states."""
    from train.gait import SHIPPED as POLICY
    from train.gait import load_policy

    act, kw = load_policy(POLICY)
    env = FourFingerRotate(**kw)
    d, ph = env.data, env.physics
    states = []
    for ep in range(episodes):
        obs, _ = env.reset(seed=ep)
        for t in range(64):
            a = act(obs)
            if t % every == 0:  # the state the step starts from, setpoints already moved
                ctrl0 = d.ctrl.copy()
                step = np.clip(a, -1, 1) * env.max_setpoint_step
                d.ctrl[:] = np.clip(d.ctrl + step, ph.ctrl_lo, ph.ctrl_hi)
                states.append(save_state(env))
                d.ctrl[:] = ctrl0
            obs, _, terminated, _, _ = env.step(a)
            if terminated:
                break

    ref = policy_step_outcomes(env, states, 0.0005, 100, "newton", 1e-12)
    rows = []
    for label, *setting in FIDELITY:
        e = policy_step_outcomes(env, states, *setting) - ref  # type: ignore[arg-type]
        yaw, pos = np.abs(e[:, 0]), np.linalg.norm(e[:, 1:4], axis=1)
        force = np.abs(e[:, 4:]).max(axis=1)
        rows.append(
            {
                "setting": label,
                "states": len(states),
                "yaw_rate_err_median": round(float(np.median(yaw)), 4),
                "yaw_rate_err_p95": round(float(np.percentile(yaw, 95)), 4),
                "pos_err_mm_median": round(float(np.median(pos)), 4),
                "pos_err_mm_p95": round(float(np.percentile(pos, 95)), 4),
                "force_err_median": round(float(np.median(force)), 4),
                "force_err_p95": round(float(np.percentile(force, 95)), 4),
                "yaw_rate_median_abs": round(float(np.median(np.abs(ref[:, 0]))), 4),
            }
        )
    return rows


TRANSFER_POLICIES = ("four_finger_sphere", "four_finger_sphere_2.5ms")  # in policies/
TRANSFER_TIMESTEPS = (0.001, 0.002, 0.0025)  # [s]; 0.05 s / timestep substeps each


def timestep_transfer(episodes: int = 100, seconds: float = 20.0) -> list[dict[str, object]]:
    """Does a policy trained on coarser physics still work on finer physics? Each policy of
    :data:`TRANSFER_POLICIES` (its training timestep in its config.json), deterministic,
    under each timestep of :data:`TRANSFER_TIMESTEPS` (20 Hz policy in every case), over
    ``episodes`` episodes of ``seconds`` from the same start grasps (the shipped env's
    cache, 2 ms): mean and median speed [rad/s] and drops."""
    from train.gait import SHIPPED, evaluate, load_policy
    from train.rotate import env_physics

    start = grasp_cache("sphere", True)
    rows = []
    for name in TRANSFER_POLICIES:
        act, kw = load_policy(SHIPPED.parent / name)
        for timestep in TRANSFER_TIMESTEPS:
            physics = env_physics(timestep)
            label = f"{timestep * 1e3:g} ms x {physics['frame_skip']}"
            # n_grasps 1: the env's own start cache is not used (start_grasps)
            env_kw = {**kw, **physics, "n_grasps": 1}
            r = evaluate(act, env_kw, episodes, seconds, start_grasps=start)
            rows.append(
                {
                    "policy": name,
                    "trained_timestep_s": kw["timestep"],
                    "physics": label,
                    "episodes": episodes,
                    "speed_rad_s": round(r["speed_rad_s"], 3),
                    "speed_median_rad_s": round(r["speed_median_rad_s"], 3),
                    "drops": int(round(r["drop_rate"] * episodes)),
                }
            )
    return rows


TRAIN_SETUPS = {  # name: (worker processes, pipelined rollouts)
    "PPO training (4x512, 16 envs in-process)": (0, False),
    "PPO training (4x512, 16 envs 2 worker processes)": (2, False),
    "PPO training (4x512, 16 envs 2 workers, pipelined: default)": (2, True),
}


def train_steps_per_second(rollouts: int = 6) -> dict[str, list[float]]:
    """PPO training throughput with train.ppo's defaults (env steps/s including updates),
    per setup of :data:`TRAIN_SETUPS`: all setups are built (and warmed up by one rollout
    and update) in this process, then take turns, one rollout + update each, ``rollouts``
    times, so that a drift of the machine's speed hits them alike."""
    import torch
    from stable_baselines3.common.vec_env import VecNormalize

    from train import rotate
    from train.seeding import RunSeeds
    from train.vec import make_vec_env

    cfg = rotate.RotateConfig()
    torch.set_num_threads(cfg.threads)
    n = cfg.n_steps * cfg.n_envs
    built = {}
    for name, (workers, pipeline) in TRAIN_SETUPS.items():
        thunks = [rotate.make_env(cfg, s) for s in RunSeeds(0).envs("train", cfg.n_envs)]
        vec = VecNormalize(make_vec_env(thunks, workers, parts=2 if pipeline else 1))
        model = rotate.build_model(cfg, vec)  # PipelinedPPO: plain PPO unless parts >= 2
        cb = rotate.RolloutThreads(cfg.threads) if workers else None
        model.learn(n, callback=cb)  # warm-up: worker start, first update
        built[name] = (model, cb, vec)
    rates: dict[str, list[float]] = {name: [] for name in built}
    for r in range(rollouts):
        order = list(built) if r % 2 == 0 else list(built)[::-1]
        for name in order:
            model, cb, _ = built[name]
            t = time.perf_counter()
            model.learn(n, callback=cb, reset_num_timesteps=False)
            rates[name].append(n / (time.perf_counter() - t))
    for _, _, vec in built.values():
        vec.close()
    return rates


def main(argv: Sequence[str] | None = None) -> list[dict[str, object]]:
    p = argparse.ArgumentParser(prog="python -m envs.bench", description=__doc__.split("\n\n")[0])
    p.add_argument("--steps", type=int, default=600, help="env steps per repeat")
    p.add_argument("--repeats", type=int, default=5, help="repeats per row (median reported)")
    p.add_argument("--env", action=argparse.BooleanOptionalAction, default=True,
                   help="measure the env rows (off: only the other parts)")  # fmt: skip
    p.add_argument("--train", action=argparse.BooleanOptionalAction, default=True,
                   help="also measure PPO training throughput")  # fmt: skip
    p.add_argument("--fidelity", action=argparse.BooleanOptionalAction, default=True,
                   help="also measure what coarser timesteps change")  # fmt: skip
    p.add_argument("--transfer", action=argparse.BooleanOptionalAction, default=False,
                   help="also evaluate policies trained at 2 and 2.5 ms under 1, 2, 2.5 ms "
                        "physics (about 10 min)")  # fmt: skip
    p.add_argument("--train-rollouts", type=int, default=6,
                   help="rollouts (6,144 steps + update) per training setup")  # fmt: skip
    p.add_argument("--out", default="bench_out", help="directory for the CSV and PNG")
    a = p.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    rows: list[dict[str, object]] = []
    if a.env:
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
    if a.train:
        rates = train_steps_per_second(a.train_rollouts)
        first = None
        for name, sps in rates.items():
            med = float(np.median(sps))
            first = first or sps
            ratio = float(np.median(np.array(sps) / np.array(first)))
            rows.append(
                {
                    "config": name,
                    "env_steps_per_s": round(med, 1),
                    "min": round(min(sps), 1),
                    "max": round(max(sps), 1),
                    "ratio_to_landed": None,
                    "ratio_to_in_process": round(ratio, 2),
                }
            )
            print(f"{name}: {med:.0f} env steps/s including updates (x{ratio:.2f} in-process)")
    if a.fidelity:
        fid = timestep_fidelity()
        _write_csv(out / "four_finger_fidelity.csv", fid)
        for r in fid:
            print(
                f"{r['setting']:32s} yaw rate error {r['yaw_rate_err_median']:.3f} "
                f"(p95 {r['yaw_rate_err_p95']:.3f}) rad/s, object {r['pos_err_mm_median']:.3f} mm, "
                f"link force {r['force_err_median']:.3f} N"
            )
    if a.transfer:
        tr = timestep_transfer()
        _write_csv(out / "four_finger_transfer.csv", tr)
        for r in tr:
            print(
                f"{r['policy']:28s} under {r['physics']:12s}: {r['speed_rad_s']:.3f} rad/s "
                f"(median {r['speed_median_rad_s']:.3f}), {r['drops']}/{r['episodes']} drops"
            )
    if not rows:
        return rows
    thesis = round(THESIS_STEPS_PER_S)
    rows.append({"config": "thesis training (server)", "env_steps_per_s": thesis})
    _write_csv(out / "four_finger_env.csv", rows)
    _plot(rows, out / "four_finger_env.png")
    print(f"wrote {out / 'four_finger_env.csv'} and {out / 'four_finger_env.png'}")
    return rows


def _write_csv(path: Path, rows: list[dict[str, object]]) -> None:
    """``rows`` as CSV, the columns the union of their keys in order of appearance."""
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(dict.fromkeys(k for r in rows for k in r)))
        w.writeheader()
        w.writerows(rows)


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
    ax.set_xlabel("env steps per second (one process; training: incl. PPO updates)")
    ax.set_xlim(0, max(vals) * 1.15 + 100)
    ax.set_title("Four-finger rotation env on this 2-core machine (dotted: 1,500 target)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
