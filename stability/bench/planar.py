"""``python -m stability.bench planar``: reproduces the thesis' Table tab:performance
(number of slip states and enumeration time for m = 2..9 random contacts) side by side
with our numbers, and extends it to m = 20 and 50. For each m it reports medians over
``--repeats`` random generic grasps (fresh grasp each repeat, fixed seed):

* ``faces``: faces of the tangential-plane arrangement (thesis ``#(S)``);
* ``joint``: co-occurring (slip, detachment) states with preload 1 (what the
  solver visits when it has to prove instability);
* ``enum_s``: time to enumerate the slip states (the thesis' timed quantity);
* ``thesis_alg_here_s``: the thesis' own enumeration (one LP per step, dual
  polyhedron, minimum cycle basis; :func:`stability.planar.slip_states_thesis`) timed
  on the same machine in the same run (median of 3, m <= 9), the reference
  for the speed-up;
* ``query_s``: time to answer one ``Existence`` query for a random wrench
  ``w ~ N(0, I)`` with preload 1 (``stable_frac``: share of stable answers);
* ``worst_s``: time for an unstable query that needs the full enumeration
  (all normals in the upper half plane, the object pulled up: nothing holds);
* ``worst_warm_s``: a second such query on the same grasp, which reuses the
  cached, factorised states (grasps with up to 200k joint states).

Writes ``planar.csv`` and ``planar.png`` (time vs m, log scale, ours vs thesis).
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..api import solve
from ..grasp import Grasp
from ..io import write_csv
from ..planar import count_slip_faces, slip_states, slip_states_thesis
from ..queries import Existence
from .plots import pyplot, save

THESIS = {  # m: (#S, seconds) from thesis Table tab:performance (2.8 GHz i7)
    2: (10, 0.006), 3: (26, 0.02), 4: (50, 0.09), 5: (82, 0.42),
    6: (122, 1.5), 7: (170, 4.8), 8: (226, 13.8), 9: (290, 35.7),
}  # fmt: skip
MS = [2, 3, 4, 5, 6, 7, 8, 9, 20, 50]


def _timed(fn: Callable[[], object]) -> tuple[float, object]:
    t0 = time.perf_counter()
    out = fn()
    return time.perf_counter() - t0, out


def random_grasp(rng: np.random.Generator, m: int, upper: bool = False) -> Grasp:
    """``m`` random generic contacts in [-1, 1]^2 with uniform normals.

    ``upper``: normals within pi/2 - 0.6 rad of +y, so with mu = 0.5 every contact force
    pushes the object up and no downward net force exists.
    """
    pts = rng.uniform(-1, 1, (m, 2))
    ang = rng.uniform(0.6, np.pi - 0.6, m) if upper else rng.uniform(0, 2 * np.pi, m)
    return Grasp(pts, np.stack([np.cos(ang), np.sin(ang)], axis=1), 0.5)


def bench_planar(repeats: int = 15, seed: int = 0, ms: list[int] | None = None) -> list[dict]:
    from tqdm import tqdm

    rows = []
    ms = ms or MS
    for m in tqdm(ms, desc="planar bench", unit="m"):
        rng = np.random.default_rng(seed + m)
        reps = repeats if m <= 20 else max(3, repeats // 3)
        enum, query, worst, warm, stable = [], [], [], [], []
        faces = joint = states = 0
        for k in range(reps):
            g = random_grasp(rng, m)
            t, S = _timed(lambda g=g: slip_states(g))
            enum.append(t)
            w = rng.normal(size=3)
            t, sol = _timed(lambda g=g, w=w: solve(g, Existence(w, preload=1.0)))
            query.append(t)
            stable.append(sol.stable)
            gu = random_grasp(rng, m, upper=True)
            t, sol = _timed(lambda gu=gu: solve(gu, Existence((0.0, 1.0, 0.0), preload=1.0)))
            assert not sol.stable
            worst.append(t)
            # same grasp again: the factorised states are cached (when <= 200k of them)
            t, sol = _timed(lambda gu=gu: solve(gu, Existence((0.0, 2.0, 0.0), preload=1.0)))
            assert not sol.stable
            warm.append(t)
            if k == 0:
                faces = count_slip_faces(g)["total"]
                states = len(S)
                joint = sol.stats["states"]
        # the thesis' own algorithm (LP per step + minimum cycle basis), same machine
        lp_enum = None
        if m <= 9:
            lp_t = []
            for _ in range(3):
                g = random_grasp(rng, m)
                lp_t.append(_timed(lambda g=g: slip_states_thesis(g))[0])
            lp_enum = float(np.median(lp_t))
        th = THESIS.get(m, (None, None))
        rows.append(
            {
                "m": m,
                "thesis_states": th[0],
                "faces": faces,
                "slip_states": states,
                "joint_states": joint,
                "thesis_time_s": th[1],
                "enum_s": float(np.median(enum)),
                "thesis_alg_here_s": lp_enum,
                "query_s": float(np.median(query)),
                "stable_frac": float(np.mean(stable)),
                "worst_s": float(np.median(worst)),
                "worst_warm_s": float(np.median(warm)),
                "repeats": reps,
            }
        )
    return rows


def write_planar(rows: list[dict], out: Path) -> tuple[Path, Path]:
    plt = pyplot()
    import matplotlib.ticker

    out.mkdir(parents=True, exist_ok=True)
    csv_path = write_csv(out / "planar.csv", rows)
    m = [r["m"] for r in rows]
    fig, ax = plt.subplots(figsize=(7, 4.5))
    tm = [r["m"] for r in rows if r["thesis_time_s"]]
    ax.semilogy(
        tm,
        [r["thesis_time_s"] for r in rows if r["thesis_time_s"]],
        "ks--",
        label="thesis: enumerate slip states (LP per step)",
    )
    hm = [r["m"] for r in rows if r["thesis_alg_here_s"]]
    ax.semilogy(
        hm,
        [r["thesis_alg_here_s"] for r in rows if r["thesis_alg_here_s"]],
        "ks:",
        mfc="none",
        label="thesis' algorithm re-implemented, this machine",
    )
    ax.semilogy(m, [r["enum_s"] for r in rows], "o-", label="ours: enumerate slip states")
    ax.semilogy(m, [r["query_s"] for r in rows], "^-", label="ours: Existence, random wrench")
    ax.semilogy(
        m, [r["worst_s"] for r in rows], "v-", label="ours: Existence, unstable (full enumeration)"
    )
    ax.semilogy(
        m, [r["worst_warm_s"] for r in rows], "x:", label="ours: same, repeated (cached states)"
    )
    ax.set_xscale("log")
    ax.set_xticks(m, [str(x) for x in m])
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_xlabel("number of contacts m")
    ax.set_ylabel("median time [s]")
    ax.set_title("Planar passive stability: time vs contacts")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return csv_path, save(fig, out / "planar.png", dpi=120)


def print_table(rows: list[dict]) -> None:
    hdr = (
        f"{'m':>3} {'#S thesis':>9} {'#S ours':>7} {'joint':>7} {'thesis s':>9} {'alg here s':>10} "
        f"{'enum ms':>8} {'speedup':>8} {'query ms':>9} {'stable':>6} {'worst ms':>9} "
        f"{'warm ms':>8}"
    )
    print(hdr)
    print("-" * len(hdr))
    for r in rows:
        ts = f"{r['thesis_time_s']:.3g}" if r["thesis_time_s"] else "-"
        here = r["thesis_alg_here_s"]
        hs = f"{here:.3g}" if here else "-"
        sp = f"{here / r['enum_s']:.0f}x" if here else "-"
        print(
            f"{r['m']:>3} {r['thesis_states'] or '-':>9} {r['faces']:>7} {r['joint_states']:>7} "
            f"{ts:>9} {hs:>10} {r['enum_s'] * 1e3:>8.2f} {sp:>8} {r['query_s'] * 1e3:>9.2f} "
            f"{r['stable_frac']:>6.2f} {r['worst_s'] * 1e3:>9.1f} {r['worst_warm_s'] * 1e3:>8.1f}"
        )


def cli(args: argparse.Namespace) -> None:
    """``python -m stability.bench planar``: options ``--repeats`` (default 15), ``--seed``,
    ``--out``."""
    rows = bench_planar(args.repeats or 15, args.seed)
    print_table(rows)
    csv_path, png = write_planar(rows, Path(args.out))
    print(f"wrote {csv_path} and {png}")
