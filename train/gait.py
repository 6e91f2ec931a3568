"""Image strip of one period of a learned rotation gait: ``python -m train.gait``.

Runs the deterministic policy of a run directory (``model.zip`` or ``policy.pt``
with ``vecnormalize.pkl``; default: the shipped ``policies/four_finger_sphere``)
on ``ihm/FourFingerRotate-v0`` from a cached start grasp for ``--seconds``,
estimates the gait period from the autocorrelation of the actuator setpoints
(the first peak after lag 0), and renders ``--frames`` evenly spaced frames of
one period from the side and from the top, as the thesis' gait figures.
Writes ``--out`` (PNG) and prints the speed over the rollout and the period.
``--episodes N`` also evaluates the policy (:func:`train.policy.evaluate`).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from stability.cli import ArgumentParser
from train.policy import SHIPPED, evaluate, load_policy
from train.runfiles import PolicyError

__all__ = ["gait_period", "main", "render_strip", "rollout"]


def rollout(
    act: Callable[[np.ndarray], np.ndarray], env_kwargs: dict, seconds: float, grasp: int
) -> dict[str, np.ndarray]:
    """States of a deterministic rollout: qpos, ctrl per step, turned angle, dropped flag."""
    from envs.four_finger import FourFingerRotate

    env = FourFingerRotate(**env_kwargs)
    obs, _ = env.reset(options={"grasp": grasp})
    qpos, ctrl, angle = [env.data.qpos.copy()], [env.data.ctrl.copy()], [0.0]
    dropped = False
    for _ in range(int(round(seconds / env.dt))):
        obs, _, term, _, info = env.step(act(obs))
        qpos.append(env.data.qpos.copy())
        ctrl.append(env.data.ctrl.copy())
        angle.append(info["rotation_angle"])
        if term:
            dropped = True
            break
    env.close()
    return {
        "qpos": np.array(qpos),
        "ctrl": np.array(ctrl),
        "angle": np.array(angle),
        "dropped": np.array(dropped),
        "dt": np.array(env.dt),
    }


def gait_period(ctrl: np.ndarray, min_lag: int = 4) -> int:
    """Period [steps] of the setpoint trajectory: lag of the highest autocorrelation peak
    after the first zero crossing (second half of the rollout, mean removed)."""
    x = ctrl[len(ctrl) // 2 :] - ctrl[len(ctrl) // 2 :].mean(axis=0)
    n = len(x)
    ac = np.array([np.sum(x[: n - k] * x[k:]) / (n - k) for k in range(n // 2)])
    ac /= ac[0] if ac[0] > 0 else 1.0
    start = max(min_lag, int(np.argmax(ac < 0)) if np.any(ac < 0) else min_lag)
    return int(start + np.argmax(ac[start:])) if start < len(ac) else min_lag


def render_strip(
    env_kwargs: dict,
    states: np.ndarray,
    ctrls: np.ndarray,
    out: Path,
    speed: float,
    period_s: float,
    title: str | None = None,
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import mujoco

    from envs.four_finger import FourFingerRotate, RenderSettings

    frames = {}
    for cam in ("side", "top"):
        view = RenderSettings(width=320, height=320, camera=cam)
        env = FourFingerRotate(**env_kwargs, render_mode="rgb_array", render=view)
        env.reset(options={"grasp": 0})
        imgs = []
        for q, c in zip(states, ctrls, strict=True):
            env.data.qpos[:] = q
            env.data.ctrl[:] = c
            mujoco.mj_forward(env.model, env.data)
            imgs.append(env.render())
        frames[cam] = imgs
        env.close()
    k = len(states)
    fig, ax = plt.subplots(2, k, figsize=(1.9 * k, 4.1))
    for row, cam in enumerate(("side", "top")):
        for j in range(k):
            ax[row, j].imshow(frames[cam][j])
            ax[row, j].set_xticks([])
            ax[row, j].set_yticks([])
            if row == 0:
                ax[row, j].set_title(f"t = {j * period_s / k:.2f} s", fontsize=8)
        ax[row, 0].set_ylabel(cam)
    fig.suptitle(
        title
        or f"one gait period ({period_s:.2f} s) of the learned policy, {speed:.2f} rad/s over the "
        "rollout (top: side view, bottom: top view)",
        fontsize=9,
    )
    fig.tight_layout()
    fig.savefig(out, dpi=100)
    plt.close(fig)


def main(argv: Sequence[str] | None = None) -> dict[str, float]:
    p = ArgumentParser(prog="python -m train.gait", description=__doc__.split("\n\n")[0])
    p.add_argument("run_dir", nargs="?", default=str(SHIPPED), help="run or policy directory")
    p.add_argument("--seconds", type=float, default=20.0, help="rollout length [s]")
    p.add_argument("--frames", type=int, default=9, help="frames per period (thesis: 9)")
    p.add_argument("--grasp", type=int, default=0, help="start grasp (cache index)")
    p.add_argument("--out", default="bench_out/four_finger_gait.png", help="PNG to write")
    p.add_argument("--title", default=None, help="figure title (default: period and speed)")
    p.add_argument(
        "--episodes",
        type=int,
        default=0,
        help="also evaluate this many --seconds episodes (start grasps seeded 10000+)",
    )
    p.add_argument("--eval-out", default=None, help="JSON file for the --episodes evaluation")
    a = p.parse_args(argv)
    os.environ.setdefault("MUJOCO_GL", "egl")
    try:
        act, env_kwargs = load_policy(Path(a.run_dir))
    except PolicyError as e:
        p.error(str(e))
    if a.episodes:
        import json

        res = evaluate(act, env_kwargs, a.episodes, a.seconds, seed=10_000)
        print(
            f"{a.run_dir}: {res['episodes']} x {a.seconds:g} s episodes: mean "
            f"{res['speed_rad_s']:.3f} rad/s (median {res['speed_median_rad_s']:.3f}, 10th "
            f"percentile {res['speed_p10_rad_s']:.3f}), drop rate {res['drop_rate']:.3f}"
        )
        if a.eval_out:
            Path(a.eval_out).write_text(json.dumps(res, indent=2) + "\n")
    r = rollout(act, env_kwargs, a.seconds, a.grasp)
    dt = float(r["dt"])
    speed = float(r["angle"][-1]) / ((len(r["angle"]) - 1) * dt)
    period = gait_period(r["ctrl"])
    start = len(r["ctrl"]) // 2
    idx = start + np.round(np.linspace(0, period, a.frames, endpoint=False)).astype(int)
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    render_strip(env_kwargs, r["qpos"][idx], r["ctrl"][idx], out, speed, period * dt, a.title)
    print(
        f"{a.run_dir}: {speed:.3f} rad/s over {(len(r['angle']) - 1) * dt:.1f} s "
        f"(dropped: {bool(r['dropped'])}), gait period {period} steps = {period * dt:.2f} s; "
        f"wrote {out}"
    )
    return {"speed_rad_s": speed, "period_s": period * dt, "dropped": float(r["dropped"])}


if __name__ == "__main__":
    main()
