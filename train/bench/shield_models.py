"""Criteria against models: ``python -m train.bench shield models``.

Separates the two reasons a grasp shield can fail: what it asks (its criteria, a
:class:`shields.ShieldLimits`) and how it predicts (its model). Each criteria set is judged
by the linearised-compliance QP shield (``qp-*``, :class:`shields.GraspShield`) and by the
lookahead shield (``lookahead-*``, :class:`shields.LookaheadShield`, a MuJoCo simulation of
the action: the perfect model). The criteria sets:

- ``thesis``: ``ShieldLimits()``: a force-closure set of links keeps every contact inside
  its friction pyramid with ``c_n >= c_min``; the object's box; tilt within 0.5 rad;
- ``grip``: the same set only keeps pressing (``friction=False``: contacts may slide), no
  tilt;
- ``drop``: the object's box only (``contacts=False``, no tilt for the sphere:
  :func:`shields.drop_limits`).

Models: the QP's linearisation (``qp-<criteria>``), plus the object's drift for ``drop``
(``qp-drift``: ``drift_steps`` 4); the one-step simulation (``lookahead-<criteria>``), plus a
horizon of 4 steps for ``drop`` (``lookahead``: the action, then 3 steps holding still).

For each agent (``random``: uniform actions; ``policy``: the shipped sphere policy) and each
shield, ``--episodes`` episodes of ``--steps`` steps (20 s) from the same start grasps as
without a shield (episode ``i``: ``reset(seed=seed + i)``, random actions from the same
stream). Per episode: drop, drop within the first 64 steps (a training episode's length),
net turn [rad/s], interventions and the shield's wall time per step. Summary per (agent,
shield): drops with Wilson 95 % intervals, mean speed, interventions per step, latency
median and 95th percentile [ms], status counts. Files: ``shield_models.csv``,
``shield_models_summary.csv``, ``shield_models.png`` under ``--out``.
"""

from __future__ import annotations

import argparse
import time
from collections import Counter
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from tqdm import tqdm

from shields import GraspShield, LookaheadShield, ShieldLimits, drop_limits, make_shield
from train.bench.shield_common import (
    AGENTS,
    csv_list,
    make_env,
    positive,
    print_table,
    pyplot,
    save,
    shipped_policy,
    wrote,
)
from train.evaluation import RotationEpisode, one_by_one, run_episodes
from train.stats import wilson_interval

__all__ = ["VARIANTS", "add_parser", "run", "run_models", "summarize_models"]

TRAINING_EPISODE = 64  # steps of a training episode


def _grip(env: gym.Env) -> ShieldLimits:
    return ShieldLimits(friction=False, tilt=False)


VARIANTS: dict[str, Callable[[gym.Env], gym.Env]] = {
    "none": lambda env: env,
    "qp-thesis": lambda env: GraspShield(env),
    "lookahead-thesis": lambda env: LookaheadShield(env),
    "qp-grip": lambda env: GraspShield(env, limits=_grip(env)),
    "lookahead-grip": lambda env: LookaheadShield(env, limits=_grip(env)),
    "qp-drop": lambda env: GraspShield(env, limits=drop_limits(env)),
    "qp-drift": lambda env: make_shield(env, "qp-drift"),
    "qp-guard": lambda env: make_shield(env, "qp-guard"),
    "lookahead-drop": lambda env: LookaheadShield(env, limits=drop_limits(env)),
    "lookahead": lambda env: make_shield(env, "lookahead"),
}
"""Name -> shield around an env (module docstring)."""


class _Episode(RotationEpisode):
    """A rotation episode with the shield's statuses and wall time per step."""

    def __init__(self, env: gym.Env, obs: Any = None, info: dict[str, Any] | None = None) -> None:
        super().__init__(env, obs, info)
        self.statuses: Counter[str] = Counter()

    def step(
        self, obs: Any, reward: float, terminated: bool, truncated: bool, info: dict[str, Any]
    ) -> bool:
        if "shield_status" in info:
            self.statuses[str(info["shield_status"])] += 1
        return super().step(obs, reward, terminated, truncated, info)

    def result(self) -> dict[str, Any]:
        r = super().result()
        t = np.array(self.shield_seconds) * 1e3
        return {
            **r,
            "dropped_64": bool(r["dropped"] and r["steps"] <= TRAINING_EPISODE),
            "ms_median": float(np.median(t)) if len(t) else 0.0,
            "ms_p95": float(np.percentile(t, 95)) if len(t) else 0.0,
            "ms": t.tolist(),
            "statuses": dict(self.statuses),
        }


def run_models(
    out: Path,
    *,
    seed: int = 0,
    episodes: int = 20,
    steps: int = 400,
    agents: Sequence[str] = AGENTS,
    variants: Sequence[str] = tuple(VARIANTS),
    progress: bool = True,
) -> list[dict[str, Any]]:
    """The measurement of the module docstring; one row per episode; writes the files."""
    rows: list[dict[str, Any]] = []
    bar = tqdm(total=len(agents) * len(variants) * episodes, desc="episodes", disable=not progress)
    for agent in agents:
        act, opts = shipped_policy() if agent == "policy" else (None, {})
        for name in variants:
            env = VARIANTS[name](make_env(opts))
            for ep in range(episodes):
                rng = np.random.default_rng([seed, ep])

                def policy(obs: Any, rng: np.random.Generator = rng, act: Any = act) -> np.ndarray:
                    a = rng.uniform(-1.0, 1.0, 12) if act is None else act(obs)
                    return np.asarray(a, dtype=np.float32)

                (r,) = run_episodes(
                    [env], 1, one_by_one(policy), _Episode,
                    reset_seed=lambda i, j, ep=ep: seed + ep, max_steps=steps,
                )  # fmt: skip
                rows.append({"agent": agent, "shield": name, "episode": ep, **r})
                bar.update()
            env.close()
    bar.close()
    csv_rows = [{k: v for k, v in r.items() if k not in ("ms", "statuses")} for r in rows]
    for r, c in zip(rows, csv_rows, strict=True):
        c["statuses"] = " ".join(f"{k}:{v}" for k, v in sorted(r["statuses"].items()))
    summary = summarize_models(rows)
    save(out, "shield_models", csv_rows, lambda _: summary, plot_models, plot_summary=True)
    return rows


def summarize_models(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per (agent, shield): drops (of the episodes and within 64 steps) with Wilson 95 %
    intervals, mean speed, interventions per step, latency median / p95 over all steps [ms],
    status counts."""
    out = []
    for agent in dict.fromkeys(r["agent"] for r in rows):
        for shield in dict.fromkeys(r["shield"] for r in rows):
            sel = [r for r in rows if r["agent"] == agent and r["shield"] == shield]
            if not sel:
                continue
            n, steps = len(sel), sum(r["steps"] for r in sel)
            drops, d64 = sum(r["dropped"] for r in sel), sum(r["dropped_64"] for r in sel)
            ms = np.concatenate([r.get("ms", []) for r in sel] + [np.zeros(0)])
            status: Counter[str] = Counter()
            for r in sel:
                status.update(r.get("statuses", {}))
            lo, hi = wilson_interval(drops, n)
            lo64, hi64 = wilson_interval(d64, n)
            out.append({
                "agent": agent, "shield": shield, "episodes": n, "steps": steps,
                "drops": drops, "drop_lo": lo, "drop_hi": hi,
                "drops_64": d64, "drop64_lo": lo64, "drop64_hi": hi64,
                "speed": float(np.mean([r["speed_rad_s"] for r in sel])),
                "interventions_per_step": sum(r["interventions"] for r in sel) / steps,
                "ms_median": float(np.median(ms)) if len(ms) else 0.0,
                "ms_p95": float(np.percentile(ms, 95)) if len(ms) else 0.0,
                "statuses": " ".join(f"{k}:{v}" for k, v in sorted(status.items())),
            })  # fmt: skip
    return out


def plot_models(summary: list[dict[str, Any]], path: Path) -> None:
    """Per agent: speed and drop rate (in 20 s and within 64 steps) for every shield."""
    plt = pyplot()
    agents = list(dict.fromkeys(s["agent"] for s in summary))
    names = list(dict.fromkeys(s["shield"] for s in summary))
    fig, axes = plt.subplots(len(agents), 2, figsize=(14, 3.8 * len(agents)), squeeze=False)
    for i, agent in enumerate(agents):
        sel = [next(s for s in summary if s["agent"] == agent and s["shield"] == n)
               for n in names]  # fmt: skip
        x = np.arange(len(names))
        colors = ["gray" if n == "none" else "C0" if n.startswith("qp") else "C2" for n in names]
        axes[i, 0].bar(x, [s["speed"] for s in sel], color=colors)
        axes[i, 0].set_title(f"{agent}: net turn [rad/s]")
        for k, (key, off, label) in enumerate(
            (("drops", -0.2, "dropped in 20 s"), ("drops_64", 0.2, "within 64 steps"))
        ):
            rate = np.array([s[key] / s["episodes"] for s in sel])
            lo_key, hi_key = (
                ("drop_lo", "drop_hi") if key == "drops" else ("drop64_lo", "drop64_hi")
            )
            err = [rate - [s[lo_key] for s in sel], [s[hi_key] for s in sel] - rate]
            axes[i, 1].bar(x + off, rate, width=0.4, yerr=err, capsize=3, color=f"C{3 + k}",
                           label=label)  # fmt: skip
        axes[i, 1].set_title(f"{agent}: drop rate (Wilson 95 %)")
        axes[i, 1].legend(fontsize=8)
        for a in axes[i]:
            a.set_xticks(x, names, rotation=30, ha="right", fontsize=8)
            a.grid(alpha=0.3, axis="y")
    n = summary[0]["episodes"] if summary else 0
    fig.suptitle(f"Shield criteria against shield models: {n} episodes of 20 s per agent and "
                 "shield, the same start grasps (blue: QP, green: lookahead)")  # fmt: skip
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def add_parser(sub: Any, common: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """The ``models`` subcommand (its options after ``common``'s)."""
    fmt = argparse.ArgumentDefaultsHelpFormatter
    e = sub.add_parser(
        "models", parents=[common], help="criteria against models: QP vs lookahead",
        formatter_class=fmt, description=(__doc__ or "").split("\n\n")[0],
    )  # fmt: skip
    e.add_argument("--episodes", type=positive, default=20, help="episodes per agent and shield")
    e.add_argument("--steps", type=positive, default=400, help="steps per episode (20 Hz)")
    e.add_argument("--agents", type=csv_list(str, AGENTS), default=list(AGENTS),
                   help="comma-separated: random,policy")  # fmt: skip
    e.add_argument("--shields", type=csv_list(str, tuple(VARIANTS)), default=list(VARIANTS),
                   help=f"comma-separated, of {list(VARIANTS)}")  # fmt: skip
    e.set_defaults(run=run, parser=e)
    return e


def run(args: argparse.Namespace) -> list[dict[str, Any]]:
    """Run the measurement from parsed options; print its table; return its summary rows."""
    out = Path(args.out)
    t0 = time.perf_counter()
    rows = run_models(
        out, seed=args.seed, episodes=args.episodes, steps=args.steps, agents=args.agents,
        variants=args.shields, progress=not args.no_progress,
    )  # fmt: skip
    summary = summarize_models(rows)
    cols = ["agent", "shield", "episodes", "drops", "drops_64", "speed",
            "interventions_per_step", "ms_median", "ms_p95", "statuses"]  # fmt: skip
    print_table(summary, cols)
    wrote(out, ("shield_models.csv", "shield_models_summary.csv", "shield_models.png"), t0)
    return summary
