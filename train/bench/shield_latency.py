"""The QP shield's wall time per step: ``python -m train.bench shield latency``.

States and actions of ``--episodes`` rollouts of ``--steps`` steps per source (``random``:
uniform random actions; ``policy``: the policy's actions); the rollouts execute the DAQP
shield's action, so the states are those the shield meets in use. At each state both
backends (``daqp``, ``osqp``; one :class:`shields.qp.GraspQP` each) shield the same action
``--repeats`` times in the order ``A B B A ...`` (``A`` alternates between states), so that
a drift of the machine's load hits both. The time is ``ShieldResult.solve_time_s``: the
whole shield call, linearisation and force-closure subset enumeration included. Grouped by
the number of touching finger links and by status: median and 95th percentile per backend;
per state the ratio ``sum(osqp) / sum(daqp)`` of its calls, median over states (all states,
and the states where QPs were solved); and how often the backends disagree (status, and
``|a_daqp - a_osqp|`` where both corrected). A few unrecorded calls warm both backends up
first. ``links_outside``: touching links whose contacts already violate their constraints at the
zero action (normal force below ``c_min``, or the force outside the inscribed friction
pyramid, as a contact sliding on MuJoCo's cone is); ``outside_frac`` the share of calls with
one.

Absolute latencies measured on a loaded machine are not final numbers; the ratio between the
backends is the more robust one. Common options and files: :mod:`train.bench.shield_common`.
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from tqdm import tqdm

from shields.qp import BACKENDS, STATUSES, GraspQP
from train.bench.shield_common import (
    AGENTS,
    csv_list,
    fmt,
    links_outside,
    make_env,
    positive,
    print_table,
    pyplot,
    quantiles,
    save,
    shipped_policy,
    wrote,
)

__all__ = ["add_parser", "plot_latency", "run", "run_latency", "summarize_latency"]


def run_latency(
    out: Path,
    *,
    seed: int = 0,
    episodes: int = 4,
    steps: int = 100,
    repeats: int = 2,
    sources: Sequence[str] = AGENTS,
    progress: bool = True,
) -> list[dict[str, Any]]:
    """The ``latency`` measurement (module docstring): one row per shield call, written to
    ``out/shield_latency.csv``; summary ``shield_latency_summary.csv``; chart
    ``shield_latency.png``. Returns the rows."""
    act, opts = shipped_policy() if "policy" in sources else (None, {})
    env = make_env(opts)
    m, d = env.model, env.data
    qps = {
        b: GraspQP(m, max_setpoint_step=env.max_setpoint_step, horizon=env.dt, backend=b)
        for b in BACKENDS
    }
    rows: list[dict[str, Any]] = []
    bar = tqdm(total=len(sources) * episodes * steps, desc="latency", disable=not progress)
    k = 0  # state counter: which backend goes first
    warm = False
    for source in sources:
        if source not in AGENTS:
            raise ValueError(f"unknown latency source {source!r}; choose from {AGENTS}")
        for ep in range(episodes):
            rng = np.random.default_rng([seed, AGENTS.index(source), ep])
            obs, _ = env.reset(seed=1000 * seed + ep)
            for t in range(steps):
                a = rng.uniform(-1.0, 1.0, 12) if source == "random" else act(obs)
                a = np.clip(np.asarray(a, dtype=np.float64), -1.0, 1.0)
                if not warm:
                    for _ in range(3):
                        for qp in qps.values():
                            qp(d, a)
                    warm = True
                first, second = BACKENDS if k % 2 == 0 else BACKENDS[::-1]
                order = [first, second, second, first] * ((repeats + 1) // 2)
                order = order[: 2 * repeats]
                res = {}
                for n, b in enumerate(order):
                    r = qps[b](d, a)
                    prob = qps[b].last_problem
                    res.setdefault(b, r)
                    rows.append(
                        {
                            "source": source,
                            "episode": ep,
                            "step": t,
                            "state": k,
                            "call": n,
                            "backend": b,
                            "status": r.status,
                            "links": len(prob.groups) if prob is not None else 0,
                            "contacts": prob.lin.m if prob is not None else 0,
                            "links_outside": links_outside(prob),
                            "candidates": r.candidates,
                            "qps": r.qps,
                            "correction": r.correction,
                            "solve_time_s": r.solve_time_s,
                        }
                    )
                diff = float(np.linalg.norm(res["daqp"].action - res["osqp"].action))
                for row in rows[-len(order) :]:
                    row["backend_action_diff"] = diff
                k += 1
                bar.update()
                obs, _, term, _, _ = env.step(res["daqp"].action.astype(np.float32))
                if term:
                    bar.update(steps - t - 1)
                    break
    bar.close()
    env.close()
    save(out, "shield_latency", rows, summarize_latency, plot_latency)
    return rows


def _state_ratios(rows: list[dict[str, Any]], solved_only: bool = False) -> NDArray:
    """Per state: sum of osqp times / sum of daqp times (states where QPs were solved by
    both backends, with ``solved_only``)."""
    t: dict[int, dict[str, float]] = {}
    solved: dict[int, bool] = {}
    for r in rows:
        t.setdefault(r["state"], {}).setdefault(r["backend"], 0.0)
        t[r["state"]][r["backend"]] += r["solve_time_s"]
        solved[r["state"]] = solved.get(r["state"], True) and r["qps"] > 0
    out = [
        v["osqp"] / v["daqp"]
        for s, v in t.items()
        if "osqp" in v and v["daqp"] > 0 and (solved[s] or not solved_only)
    ]
    return np.array(out)


def summarize_latency(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per backend and group (``links`` = touching finger links, ``status``, ``all``): calls,
    median and 95th percentile of the wall time [ms]; plus the per-state osqp/daqp ratio."""
    out = []
    for b in BACKENDS:
        rb = [r for r in rows if r["backend"] == b]
        groups: list[tuple[str, Any, list]] = [("all", "all", rb)]
        for n in sorted({r["links"] for r in rb}):
            groups.append(("links", n, [r for r in rb if r["links"] == n]))
        for s in STATUSES:
            groups.append(("status", s, [r for r in rb if r["status"] == s]))
        for by, value, sel in groups:
            if not sel:
                continue
            med, p95 = quantiles([1e3 * r["solve_time_s"] for r in sel], (0.5, 0.95))
            out.append(
                {"backend": b, "by": by, "group": value, "calls": len(sel),
                 "median_ms": med, "p95_ms": p95,
                 "mean_qps": float(np.mean([r["qps"] for r in sel])),
                 "outside_frac": float(np.mean([r["links_outside"] > 0 for r in sel]))}
            )  # fmt: skip
    first = {}
    for r in rows:
        first.setdefault(r["state"], {}).setdefault(r["backend"], r)
    pairs = [v for v in first.values() if len(v) == len(BACKENDS)]
    differ = sum(len({v[b]["status"] for b in BACKENDS}) > 1 for v in pairs)
    both = [v["daqp"]["backend_action_diff"] for v in pairs
            if all(v[b]["status"] == "corrected" for b in BACKENDS)]  # fmt: skip
    med, mx = quantiles(both, (0.5, 1.0))
    out.append(
        {"backend": "osqp vs daqp", "by": "agreement", "group": "states", "calls": len(pairs),
         "status_differs": differ, "action_diff_med": med, "action_diff_max": mx}
    )  # fmt: skip
    for tag, solved in (("all states", False), ("states with QPs", True)):
        ratio = _state_ratios(rows, solved)
        med, p5, p95 = quantiles(ratio, (0.5, 0.05, 0.95))
        out.append(
            {"backend": "osqp/daqp", "by": "ratio", "group": tag, "calls": len(ratio),
             "median_ms": med, "p95_ms": p95, "p05": p5}
        )  # fmt: skip
    return out


def plot_latency(rows: list[dict[str, Any]], path: Path) -> None:
    """Box plots of the wall time per backend by touching links and by status (log y),
    and the histogram of the per-state osqp/daqp ratio."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(16, 5), gridspec_kw={"width_ratios": [3, 2, 2]})
    for ax, by, values in (
        (axes[0], "links", sorted({r["links"] for r in rows})),
        (axes[1], "status", [s for s in STATUSES if any(r["status"] == s for r in rows)]),
    ):
        data, pos, colors, ticks = [], [], [], []
        for i, v in enumerate(values):
            for j, b in enumerate(BACKENDS):
                x = [1e3 * r["solve_time_s"] for r in rows if r["backend"] == b and r[by] == v]
                if x:
                    data.append(x)
                    pos.append(3 * i + j)
                    colors.append(f"C{j}")
            ticks.append(3 * i + 0.5)
        if data:
            bp = ax.boxplot(data, positions=pos, widths=0.8, whis=(5, 95), showfliers=False,
                            patch_artist=True)  # fmt: skip
            for patch, c in zip(bp["boxes"], colors, strict=True):
                patch.set_facecolor(c)
                patch.set_alpha(0.6)
        ax.set_xticks(ticks)
        counts = [
            "/".join(str(sum(r[by] == v and r["backend"] == b for r in rows)) for b in BACKENDS)
            for v in values
        ]
        ax.set_xticklabels([f"{v}\n({c} calls)" for v, c in zip(values, counts, strict=True)])
        ax.set_yscale("log")
        ax.set_ylabel("shield call wall time [ms] (box: quartiles, whiskers 5-95 %)")
        what = "touching finger links" if by == "links" else "status"
        ax.set_xlabel(f"{what} (calls: {' / '.join(BACKENDS)})")
        ax.grid(alpha=0.3, which="both", axis="y")
    for j, b in enumerate(BACKENDS):
        axes[0].plot([], [], color=f"C{j}", lw=8, alpha=0.6, label=b)
    axes[0].legend()
    ratio = _state_ratios(rows)
    solved = _state_ratios(rows, True)
    if len(ratio):
        bins = np.geomspace(max(ratio.min(), 1e-2), max(ratio.max(), 1.1), 40)
        label = f"all states (median {np.median(ratio):.2f})"
        axes[2].hist(ratio, bins=bins, alpha=0.5, label=label)
        if len(solved):
            axes[2].hist(solved, bins=bins, alpha=0.5,
                         label=f"states with QPs (median {np.median(solved):.2f})")  # fmt: skip
        axes[2].axvline(1.0, color="gray", lw=0.8)
        axes[2].set_xscale("log")
        axes[2].legend(fontsize=8)
    axes[2].set_xlabel("osqp / daqp time at the same state")
    axes[2].set_ylabel("states")
    fig.suptitle("QP shield latency per step (whole call: linearisation, subsets, QPs)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _print_latency(summary: list[dict[str, Any]]) -> None:
    print("\nshield wall time per call [ms]:")
    rows = [s for s in summary if s["by"] not in ("ratio", "agreement")]
    cols = ["backend", "by", "group", "calls", "median_ms", "p95_ms", "mean_qps", "outside_frac"]
    print_table(rows, cols, 3)
    for s in summary:
        if s["by"] == "agreement":
            print(
                f"backends at the same state: statuses differ at {s['status_differs']} of "
                f"{s['calls']} states; |a_daqp - a_osqp| where both corrected: median "
                f"{fmt(s['action_diff_med'], 2)}, max {fmt(s['action_diff_max'], 2)}"
            )
    ratio = {s["group"]: s for s in summary if s["by"] == "ratio"}
    for tag, s in ratio.items():
        print(
            f"osqp/daqp per state, {tag}: median {fmt(s['median_ms'], 2)} "
            f"(5-95 %: {fmt(s['p05'], 2)}-{fmt(s['p95_ms'], 2)}, {s['calls']} states)"
        )
    r = ratio.get("all states", {}).get("median_ms", math.nan)
    if np.isfinite(r):
        faster, x = ("daqp", r) if r >= 1 else ("osqp", 1 / r)
        print(f"faster: {faster} (x{x:.2f} per state, median)")


def add_parser(sub: Any, common: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """The ``latency`` subcommand (its options after ``common``'s)."""
    fmt = argparse.ArgumentDefaultsHelpFormatter
    lat = sub.add_parser(
        "latency", parents=[common], help="shield wall time per backend", formatter_class=fmt,
        description=(__doc__ or "").split("\n\n")[0],
    )  # fmt: skip
    lat.add_argument("--episodes", type=positive, default=4, help="rollouts per source")
    lat.add_argument("--steps", type=positive, default=100, help="steps per rollout")
    lat.add_argument("--repeats", type=positive, default=2, help="calls per backend and state")
    lat.add_argument("--sources", type=csv_list(str, AGENTS), default=list(AGENTS),
                     help="comma-separated: random,policy")  # fmt: skip
    lat.set_defaults(run=run, parser=lat)
    return lat


def run(args: argparse.Namespace) -> list[dict[str, Any]]:
    """Run the measurement from parsed options; print its table; return its summary rows."""
    out = Path(args.out)
    t0 = time.perf_counter()
    rows = run_latency(
        out, seed=args.seed, episodes=args.episodes, steps=args.steps, repeats=args.repeats,
        sources=args.sources, progress=not args.no_progress,
    )  # fmt: skip
    summary = summarize_latency(rows)
    _print_latency(summary)
    wrote(out, ("shield_latency.csv", "shield_latency_summary.csv", "shield_latency.png"), t0)
    return summary
