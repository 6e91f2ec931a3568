"""The QP shield's effect on episodes: ``python -m train.bench shield effect``.

``--episodes`` episodes of ``--steps`` steps (400 = 20 s) per agent (``random``,
``policy``), each without a shield and with ``shields.GraspShield`` (DAQP), episode ``i``
from the same start grasp in both (``env.reset(seed=seed + i)``; the random agent's action
stream is seeded with ``(seed, i)`` too). A drop ends an episode. Per episode: dropped;
rotation speed = turned angle about +z / episode time [rad/s] (as
``train.evaluation.evaluate_rotation``); slip events; contact losses; shield interventions
(``info["shield_intervened"]``: statuses ``corrected`` and ``fallback``), status counts and
``|a~ - clip(a)|`` (mean over shielded steps); ``steps_outside``: shielded steps at whose
start some touching link was already outside its constraints (``shield_latency``,
``links_outside``). Summary per agent and shield: drop rate with its Wilson 95 % interval
(:func:`train.stats.wilson_interval`), means with t-based 95 % intervals over episodes, and
the paired speed difference (shield - none).

Slip events and contact losses are defined in :mod:`train.bench.shield_common`, as are the
common options and files. An episode runs through the evaluation loop of
:mod:`train.evaluation` (:class:`ShieldEpisode`, a :class:`train.evaluation.RotationEpisode`
with the slip and contact measures).
"""

from __future__ import annotations

import argparse
import math
import time
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
from tqdm import tqdm

from envs.four_finger import FourFingerRotate
from shields.qp import STATUSES, ShieldLimits
from shields.wrappers import GraspShield
from train.bench.shield_common import (
    AGENTS,
    SLIP_RATIO,
    Links,
    Policy,
    cone_ratios,
    csv_list,
    links_outside,
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

__all__ = [
    "ShieldEpisode",
    "add_parser",
    "effect_name",
    "plot_effect",
    "run",
    "run_effect",
    "run_episode",
    "summarize_effect",
]

_CONE = int(mujoco.mjtConstraintState.mjCNSTRSTATE_CONE)


class ShieldEpisode(RotationEpisode):
    """A :class:`train.evaluation.RotationEpisode` with the per-episode measures of the module
    docstring: the start grasp, slip events, slipping contacts (by cone ratio and by MuJoCo's
    ``efc_state``), contact losses, shield statuses, steps that start outside the shield's
    constraints and the mean correction."""

    def __init__(self, env: gym.Env, obs: Any, info: dict[str, Any]) -> None:
        super().__init__(env, obs, info)
        base = env.unwrapped
        self.data = base.data
        self.links = Links(base.model)
        self.qp = env.qp if isinstance(env, GraspShield) else None
        self.grasp = int(info["grasp"])
        self.before = self.links.touching(self.data)
        self.slips = self.slip_contacts = self.slip_cone = self.losses = self.outside = 0
        self.corrections: list[float] = []
        self.statuses: Counter[str] = Counter()

    def step(
        self, obs: Any, reward: float, terminated: bool, truncated: bool, info: dict[str, Any]
    ) -> bool:
        super().step(obs, reward, terminated, truncated, info)
        d = self.data
        cs = self.links.contacts(d)
        after = {k for k, _ in cs}
        self.losses += len(self.before - after)
        self.before = after
        ratios = cone_ratios(d, [i for _, i in cs])
        slipping = [i for (_, i), r in zip(cs, ratios, strict=True) if r >= SLIP_RATIO]
        self.slips += bool(slipping)
        self.slip_contacts += len(slipping)
        self.slip_cone += sum(int(d.efc_state[d.contact[i].efc_address]) == _CONE for i in slipping)
        if "shield_status" in info:
            self.statuses[info["shield_status"]] += 1
            if self.qp is not None and links_outside(self.qp.last_problem) > 0:
                self.outside += 1
            self.corrections.append(float(info["shield_correction"]))
        return False

    def result(self) -> dict[str, Any]:
        r = super().result()
        row: dict[str, Any] = {
            "grasp": self.grasp,
            "steps": r["steps"],
            "dropped": r["dropped"],
            "speed_rad_s": r["speed_rad_s"],
            "slip_events": self.slips,
            "slip_contacts": self.slip_contacts,
            "slip_contacts_cone_state": self.slip_cone,
            "contact_losses": self.losses,
            "interventions": r["interventions"],
            "steps_outside": self.outside,
            "mean_correction": float(np.mean(self.corrections)) if self.corrections else 0.0,
        }
        row.update({s: self.statuses.get(s, 0) for s in STATUSES})
        return row


def run_episode(
    env: FourFingerRotate | GraspShield,
    act: Policy | None,
    *,
    seed: int,
    action_seed: Sequence[int],
    steps: int,
) -> dict[str, Any]:
    """One episode of at most ``steps`` steps from the grasp of ``env.reset(seed=seed)``
    (``act`` None: uniform random actions from ``default_rng(action_seed)``); the
    per-episode metrics of the module docstring (:class:`ShieldEpisode`)."""
    rng = np.random.default_rng(list(action_seed))

    def policy(obs: Any) -> np.ndarray:
        a = rng.uniform(-1.0, 1.0, 12) if act is None else act(obs)
        return np.asarray(a, dtype=np.float32)

    (row,) = run_episodes(
        [env], 1, one_by_one(policy), ShieldEpisode, reset_seed=lambda i, ep: seed, max_steps=steps
    )
    return {"seed": seed, **row}


def effect_name(relax_contacts: bool, soft_closure: bool) -> str:
    """File stem of an ``effect`` run: ``shield_effect[_relaxed][_soft]``."""
    return "shield_effect" + "_relaxed" * relax_contacts + "_soft" * soft_closure


def run_effect(
    out: Path,
    *,
    seed: int = 0,
    episodes: int = 40,
    steps: int = 400,
    agents: Sequence[str] = AGENTS,
    progress: bool = True,
    relax_contacts: bool = False,
    soft_closure: bool = False,
) -> list[dict[str, Any]]:
    """The ``effect`` measurement (module docstring): one row per episode, written to
    ``out/shield_effect.csv``; summary ``shield_effect_summary.csv``; chart
    ``shield_effect.png`` (``shield_effect_relaxed*``, ``shield_effect_soft*`` with
    ``relax_contacts``, ``soft_closure``: those :class:`shields.qp.ShieldLimits`
    options). Returns the rows."""
    name = effect_name(relax_contacts, soft_closure)
    limits = ShieldLimits(relax_contacts=relax_contacts, soft_closure=soft_closure)
    rows: list[dict[str, Any]] = []
    bar = tqdm(total=len(agents) * episodes * 2, desc="effect episodes", disable=not progress)
    for agent in agents:
        if agent not in AGENTS:
            raise ValueError(f"unknown agent {agent!r}; choose from {AGENTS}")
        act, opts = shipped_policy() if agent == "policy" else (None, {})
        bare = make_env(opts)
        shielded = GraspShield(make_env(opts), backend="daqp", limits=limits)
        for ep in range(episodes):
            for shield, env in (("none", bare), ("qp", shielded)):
                row = {"agent": agent, "shield": shield, "episode": ep}
                row.update(
                    run_episode(env, act, seed=seed + ep, action_seed=(seed, ep), steps=steps)
                )
                rows.append(row)
                bar.update()
        bare.close()
        shielded.close()
    bar.close()
    save(out, name, rows, summarize_effect, plot_effect, plot_summary=True)
    return rows


def _mean_ci(x: Sequence[float]) -> tuple[float, float, float]:
    """Mean and its t-based 95 % interval."""
    from scipy.stats import t as student

    x = np.asarray(x, dtype=float)
    mean = float(np.mean(x)) if len(x) else math.nan
    if len(x) < 2:
        return mean, math.nan, math.nan
    half = float(student.ppf(0.975, len(x) - 1) * np.std(x, ddof=1) / np.sqrt(len(x)))
    return mean, mean - half, mean + half


def summarize_effect(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per (agent, shield): drop rate with its Wilson 95 % interval, speed, slip events,
    contact losses (means with 95 % intervals), intervention rate per step, status counts,
    mean correction; and the paired speed difference shield - none."""
    out = []
    for agent in dict.fromkeys(r["agent"] for r in rows):
        for shield in ("none", "qp"):
            sel = [r for r in rows if r["agent"] == agent and r["shield"] == shield]
            if not sel:
                continue
            n = len(sel)
            drops = sum(r["dropped"] for r in sel)
            lo, hi = wilson_interval(drops, n)
            steps = sum(r["steps"] for r in sel)
            s: dict[str, Any] = {
                "agent": agent, "shield": shield, "episodes": n, "steps": steps,
                "drops": drops, "drop_rate": drops / n, "drop_lo": lo, "drop_hi": hi,
            }  # fmt: skip
            for key, name in (
                ("speed_rad_s", "speed"),
                ("slip_events", "slips"),
                ("contact_losses", "losses"),
            ):
                s[name], s[f"{name}_lo"], s[f"{name}_hi"] = _mean_ci([r[key] for r in sel])
            s["slip_step_frac"] = sum(r["slip_events"] for r in sel) / steps
            s["slip_frac"], s["slip_frac_lo"], s["slip_frac_hi"] = _mean_ci(
                [r["slip_events"] / r["steps"] for r in sel]
            )
            sc = sum(r["slip_contacts"] for r in sel)
            s["cone_state_agree"] = (
                sum(r["slip_contacts_cone_state"] for r in sel) / sc if sc else math.nan
            )
            iv = sum(r["interventions"] for r in sel)
            s["intervention_rate"] = iv / steps
            s["outside_rate"] = sum(r["steps_outside"] for r in sel) / steps
            for st in STATUSES:
                s[st] = sum(r[st] for r in sel)
            shielded_steps = sum(r[st] for r in sel for st in STATUSES)
            s["mean_correction"] = (
                sum(r["mean_correction"] * sum(r[st] for st in STATUSES) for r in sel)
                / shielded_steps
                if shielded_steps
                else 0.0
            )
            out.append(s)
        pairs = {}
        for r in rows:
            if r["agent"] == agent:
                pairs.setdefault(r["episode"], {})[r["shield"]] = r["speed_rad_s"]
        diffs = [p["qp"] - p["none"] for p in pairs.values() if len(p) == 2]
        for s in out:
            if s["agent"] == agent and s["shield"] == "qp":
                s["speed_diff"], s["speed_diff_lo"], s["speed_diff_hi"] = _mean_ci(diffs)
    return out


def plot_effect(summary: list[dict[str, Any]], path: Path) -> None:
    """Bars with 95 % intervals: drop rate (Wilson), speed, slip events and contact losses
    per episode, intervention rate; grouped by agent, coloured by shield."""
    plt = pyplot()
    panels = (
        ("drop_rate", "drop_lo", "drop_hi", "drop rate (Wilson 95 %)"),
        ("speed", "speed_lo", "speed_hi", "rotation speed [rad/s]"),
        ("slips", "slips_lo", "slips_hi", "slip events per episode"),
        ("slip_frac", "slip_frac_lo", "slip_frac_hi", "share of an episode's steps with a slip"),
        ("losses", "losses_lo", "losses_hi", "contact losses per episode"),
        ("intervention_rate", None, None, "shield interventions per step"),
    )
    agents = list(dict.fromkeys(s["agent"] for s in summary))
    fig, axes = plt.subplots(1, len(panels), figsize=(20, 4.5))
    for ax, (key, lo, hi, title) in zip(axes, panels, strict=True):
        for j, shield in enumerate(("none", "qp")):
            xs, ys, err = [], [], [[], []]
            for i, agent in enumerate(agents):
                s = next((s for s in summary if s["agent"] == agent and s["shield"] == shield),
                         None)  # fmt: skip
                if s is None:
                    continue
                xs.append(i + (j - 0.5) * 0.38)
                ys.append(s[key])
                low = s[lo] if lo and np.isfinite(s[lo]) else s[key]
                high = s[hi] if hi and np.isfinite(s[hi]) else s[key]
                err[0].append(s[key] - low)
                err[1].append(high - s[key])
            ax.bar(xs, ys, width=0.36, yerr=err, capsize=4, color=f"C{j}",
                   label="no shield" if shield == "none" else "QP shield (daqp)")  # fmt: skip
        ax.set_xticks(range(len(agents)))
        ax.set_xticklabels(agents)
        ax.set_title(title, fontsize=10)
        ax.grid(alpha=0.3, axis="y")
    axes[0].legend(fontsize=8)
    n = summary[0]["episodes"] if summary else 0
    fig.suptitle(f"Effect of the QP shield: {n} paired episodes per agent (same start grasps)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _print_effect(summary: list[dict[str, Any]]) -> None:
    print("\nwith and without the QP shield (means over episodes, [95 % interval]):")
    table = []
    for s in summary:
        t = {
            "agent": s["agent"],
            "shield": s["shield"],
            "eps": s["episodes"],
            "drops": f"{s['drops']}/{s['episodes']} [{s['drop_lo']:.2f}, {s['drop_hi']:.2f}]",
            "speed rad/s": f"{s['speed']:.3f} [{s['speed_lo']:.3f}, {s['speed_hi']:.3f}]",
            "slips/ep": f"{s['slips']:.1f} [{s['slips_lo']:.1f}, {s['slips_hi']:.1f}]",
            "slip steps": f"{s['slip_step_frac']:.2f}",
            "losses/ep": f"{s['losses']:.1f}",
            "interv./step": f"{s['intervention_rate']:.3f}",
            "outside/step": f"{s['outside_rate']:.3f}",
            "safe/corr/fallb/noclos": "/".join(str(s[st]) for st in STATUSES),
            "mean corr.": f"{s['mean_correction']:.3f}",
        }
        table.append(t)
    print_table(table, list(table[0]) if table else [])
    for s in summary:
        if np.isfinite(s["cone_state_agree"]):
            print(
                f"{s['agent']}, shield {s['shield']}: {s['cone_state_agree']:.0%} of the slipping "
                "contacts (cone ratio >= 0.99) have efc_state == mjCNSTRSTATE_CONE"
            )
    for s in summary:
        if "speed_diff" in s:
            print(
                f"{s['agent']}: paired speed difference shield - none: {s['speed_diff']:+.3f} "
                f"rad/s [{s['speed_diff_lo']:+.3f}, {s['speed_diff_hi']:+.3f}]"
            )


def add_parser(sub: Any, common: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """The ``effect`` subcommand (its options after ``common``'s)."""
    fmt = argparse.ArgumentDefaultsHelpFormatter
    e = sub.add_parser(
        "effect", parents=[common], help="with vs without the shield", formatter_class=fmt,
        description=(__doc__ or "").split("\n\n")[0],
    )  # fmt: skip
    e.add_argument("--episodes", type=positive, default=40, help="paired episodes per agent")
    e.add_argument("--steps", type=positive, default=400, help="steps per episode (20 Hz)")
    e.add_argument("--agents", type=csv_list(str, AGENTS), default=list(AGENTS),
                   help="comma-separated: random,policy")  # fmt: skip
    e.add_argument(
        "--relax-contacts",
        action="store_true",
        help="the shield with ShieldLimits(relax_contacts=True) (an ablation)",
    )
    e.add_argument(
        "--soft-closure",
        action="store_true",
        help="the shield with ShieldLimits(soft_closure=True) (an ablation)",
    )
    e.set_defaults(run=run, parser=e)
    return e


def run(args: argparse.Namespace) -> list[dict[str, Any]]:
    """Run the measurement from parsed options; print its table; return its summary rows."""
    out = Path(args.out)
    t0 = time.perf_counter()
    rows = run_effect(
        out, seed=args.seed, episodes=args.episodes, steps=args.steps, agents=args.agents,
        progress=not args.no_progress, relax_contacts=args.relax_contacts,
        soft_closure=args.soft_closure,
    )  # fmt: skip
    summary = summarize_effect(rows)
    _print_effect(summary)
    stem = effect_name(args.relax_contacts, args.soft_closure)
    wrote(out, (f"{stem}.csv", f"{stem}_summary.csv", f"{stem}.png"), t0)
    return summary
