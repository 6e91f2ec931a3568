"""Resistible-force maps: the largest force a grasp resists, per direction in a plane.

For each direction ``u`` (unit force in the chosen plane, zero torque and
zero out-of-plane force) the map holds ``max s`` such that the wrench
``w = s u`` is stable for ``method``: exact per direction for ``planar``
(MaxDisturbance is an LP per contact state), the L1 grasp wrench space for
``gws``. This is the thesis' Fig. bin_no_preload / bin_preload / GWS
(section "Applications to planar grasp stability analysis"), without the
binary search the thesis used.

Run ``python -m stability.maps`` to draw the thesis' three-panel figure for
its 3-contact grasp.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .api import solve
from .cli import ArgumentParser
from .errors import GraspError
from .grasp import Grasp
from .planar import max_disturbance_map
from .queries import MaxDisturbance

__all__ = [
    "ResistibleMap",
    "label_plane",
    "plane_axes",
    "plot_resistible",
    "radial_top",
    "resistible_forces",
    "thesis_figure",
]

_AXES = {"x": 0, "y": 1, "z": 2}


def plane_axes(plane: str) -> tuple[int, int]:
    """Indices of the two force axes a plane name such as ``"xy"`` or ``"zx"`` names;
    :class:`GraspError` unless it names two distinct axes of x, y, z."""
    if len(plane) != 2 or any(a not in _AXES for a in plane) or plane[0] == plane[1]:
        raise GraspError(f"plane must name two distinct force axes such as 'xy', got {plane!r}")
    return _AXES[plane[0]], _AXES[plane[1]]


@dataclass(frozen=True)
class ResistibleMap:
    """Result of :func:`resistible_forces`.

    ``angles`` [rad] measured from the plane's first axis towards its second;
    ``magnitudes`` [N]: the largest resistible force per direction (0 where
    even an infinitesimal force is not resisted, NaN where the method gave no
    answer: a time-out, not converged, an error); ``capped``: True where the
    search stopped at ``cap`` (resists *at least* ``cap``).
    """

    angles: NDArray[np.float64]
    magnitudes: NDArray[np.float64]
    capped: NDArray[np.bool_]
    cap: float
    plane: str
    method: str


def resistible_forces(
    grasp: Grasp,
    method: str = "planar",
    plane: str = "xy",
    directions: int = 360,
    preload: float | ArrayLike | None = None,
    commands: ArrayLike | None = None,
    cap: float = 10.0,
    progress: bool = False,
    **options: Any,
) -> ResistibleMap:
    """Sweep ``directions`` force directions in ``plane`` and solve MaxDisturbance for each.

    ``plane`` names two force axes (``"xy"``; spatial grasps also ``"xz"``,
    ``"yz"``); the remaining force and all torque components are zero.
    ``method="planar"`` answers all directions in one batch
    (:func:`stability.planar.max_disturbance_map`, the same answers as one
    ``solve`` per direction); other methods solve direction by direction
    (``progress=True`` shows a bar).
    """
    i, j = plane_axes(plane)
    if not isinstance(grasp, Grasp):
        raise GraspError(f"grasp must be a stability.Grasp, got {type(grasp).__name__}")
    if grasp.planar and plane != "xy":
        raise GraspError(f"a planar grasp has only the 'xy' force plane, got {plane!r}")
    if int(directions) < 1:
        raise GraspError(f"directions must be >= 1, got {directions}")
    angles = np.linspace(0.0, 2 * np.pi, int(directions), endpoint=False)
    D = np.zeros((len(angles), grasp.wrench_dim))
    D[:, i], D[:, j] = np.cos(angles), np.sin(angles)
    if method == "planar":
        mags, capped, _ = max_disturbance_map(grasp, D, preload, commands, cap, **options)
        return ResistibleMap(angles, mags, capped, float(cap), plane, method)
    mags = np.zeros(len(angles))
    capped = np.zeros(len(angles), dtype=bool)
    it = range(len(angles))
    if progress:
        from tqdm import tqdm

        it = tqdm(it, desc=f"{method} map", unit="dir")
    for k in it:
        q = MaxDisturbance(direction=D[k], preload=preload, commands=commands, cap=cap)
        sol = solve(grasp, q, method=method, **options)
        if sol.status != "solved":  # no answer is not "not resisted"
            mags[k] = np.nan
        else:
            mags[k] = sol.value if sol.stable and sol.value is not None else 0.0
        capped[k] = bool(sol.stats.get("capped", False))
    return ResistibleMap(angles, mags, capped, float(cap), plane, method)


def radial_top(rmap: ResistibleMap) -> float:
    """The polar chart's outer radius [N] for ``rmap``: just beyond the cap where a direction
    reached it, else just beyond the largest finite answer (the cap where there is none)."""
    finite = rmap.magnitudes[np.isfinite(rmap.magnitudes)]
    if rmap.capped.any() or not finite.size or finite.max() <= 0:
        return rmap.cap * 1.05
    return float(min(finite.max() * 1.1, rmap.cap * 1.05))


def label_plane(ax: Any, plane: str) -> None:
    """Name the plane's axes at 0 and 90 degrees of a polar chart (angles from the plane's
    first axis towards its second, :class:`ResistibleMap`)."""
    ax.set_xticks(np.radians([0, 90, 180, 270]))
    a, b = plane[0], plane[1]
    ax.set_xticklabels([f"+{a}", f"+{b}", f"-{a}", f"-{b}"])


def plot_resistible(ax: Any, rmap: ResistibleMap, title: str = "", color: str = "C0") -> None:
    """Draw a map on a matplotlib polar axis; capped directions are hatched (">= cap"); the
    radius reaches just beyond the map (:func:`radial_top`), the axes are named
    (:func:`label_plane`)."""
    th = np.r_[rmap.angles, rmap.angles[:1]]
    r = np.r_[rmap.magnitudes, rmap.magnitudes[:1]]
    ax.fill(th, np.nan_to_num(r), color=color, alpha=0.35, lw=0)  # (a gap where unanswered)
    ax.plot(th, r, color=color, lw=1.5)
    if rmap.capped.any():
        cap_r = np.where(np.r_[rmap.capped, rmap.capped[:1]], rmap.cap, np.nan)
        ax.plot(th, cap_r, color="k", lw=3, label=f">= cap ({rmap.cap:g} N)")
        ax.legend(loc="lower left", fontsize=7, bbox_to_anchor=(-0.15, -0.15))
    ax.set_ylim(0, radial_top(rmap))
    label_plane(ax, rmap.plane)
    ax.set_title(title, fontsize=9)


def thesis_figure(out: str | Path, directions: int = 360, cap: float = 3.0) -> Path:
    """The thesis' Fig. (a)(b)(c) for its 3-contact grasp: planar P=0, P=1, and the GWS slice."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    g = _thesis_grasp()
    panels = [
        (
            resistible_forces(g, "planar", directions=directions, preload=0.0, cap=cap),
            "planar, no preload",
            "C0",
        ),
        (
            resistible_forces(g, "planar", directions=directions, preload=1.0, cap=cap),
            "planar, preload 1 per contact",
            "C2",
        ),
        (
            resistible_forces(g, "gws", directions=directions, cap=cap),
            "GWS slice (L1, sum c_n <= 1), tz = 0",
            "C3",
        ),
    ]
    fig, axes = plt.subplots(1, 3, subplot_kw={"projection": "polar"}, figsize=(12, 4.4))
    for ax, (rmap, title, color) in zip(axes, panels, strict=True):
        plot_resistible(ax, rmap, title, color)
    fig.suptitle(
        "Resistible forces (fx, fy) [N], contacts (-1,0), (0,-1), (1,0), mu = 0.5"
        " (thesis ch. 4 figure)",
        fontsize=10,
    )
    fig.tight_layout()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out


def _thesis_grasp() -> Grasp:
    return Grasp(points=[[-1, 0], [0, -1], [1, 0]], normals=[[1, 0], [0, 1], [-1, 0]], mu=0.5)


def bench(
    directions: int = 360, repeats: int = 7, loop_repeats: int = 3, cap: float = 10.0
) -> list[dict[str, float]]:
    """Time the thesis grasp's planar map, batched against one ``solve`` per direction.

    Per preload (0 and 1 N per contact): ``batched_cold_ms``, the map on a fresh
    :class:`Grasp` (state enumeration and factorisation included, as on a first call);
    ``batched_warm_ms``, a second map on the same grasp (cached states); ``loop_ms``,
    ``directions`` calls of ``solve(..., method="planar")`` on a fresh grasp (one solve per
    direction, as the other methods' maps run). Medians over ``repeats`` (batched) and
    ``loop_repeats`` (loop) runs, interleaved so that machine noise hits all alike;
    ``max_rel_diff``: the largest difference of the two maps relative to ``max(1, value)``.
    """
    import time

    angles = np.linspace(0.0, 2 * np.pi, directions, endpoint=False)
    D = np.stack([np.cos(angles), np.sin(angles), np.zeros(directions)], axis=1)
    preloads = (0.0, 1.0)
    cold: dict[float, list[float]] = {p: [] for p in preloads}
    warm: dict[float, list[float]] = {p: [] for p in preloads}
    loop: dict[float, list[float]] = {p: [] for p in preloads}
    diff = dict.fromkeys(preloads, 0.0)
    for r in range(max(repeats, loop_repeats)):
        for p in preloads:
            if r < repeats:
                g = _thesis_grasp()
                t0 = time.perf_counter()
                vals, _, _ = max_disturbance_map(g, D, p, cap=cap)
                t1 = time.perf_counter()
                max_disturbance_map(g, D, p, cap=cap)
                t2 = time.perf_counter()
                cold[p].append(t1 - t0)
                warm[p].append(t2 - t1)
            if r < loop_repeats:
                g = _thesis_grasp()
                ref = np.zeros(directions)
                t0 = time.perf_counter()
                for k, d in enumerate(D):
                    sol = solve(g, MaxDisturbance(direction=d, preload=p, cap=cap), method="planar")
                    ref[k] = sol.value if sol.stable else 0.0
                loop[p].append(time.perf_counter() - t0)
                err = np.abs(vals - ref) / np.maximum(1.0, np.abs(ref))
                diff[p] = max(diff[p], float(err.max()))
    return [
        {
            "preload": p,
            "batched_cold_ms": 1e3 * float(np.median(cold[p])),
            "batched_warm_ms": 1e3 * float(np.median(warm[p])),
            "loop_ms": 1e3 * float(np.median(loop[p])),
            "speedup_cold": float(np.median(loop[p]) / np.median(cold[p])),
            "max_rel_diff": diff[p],
        }
        for p in preloads
    ]


def main(argv: list[str] | None = None) -> None:
    ap = ArgumentParser(prog="python -m stability.maps", description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="bench_out/planar_maps.png", help="PNG path")
    ap.add_argument("--directions", type=int, default=360)
    ap.add_argument(
        "--bench",
        action="store_true",
        help="time the thesis grasp's map, batched vs one solve per direction (no figure)",
    )
    ap.add_argument("--repeats", type=int, default=7, help="--bench: batched repeats")
    ap.add_argument("--loop-repeats", type=int, default=3, help="--bench: loop repeats")
    ap.add_argument("--cap", type=float, default=10.0, help="--bench: MaxDisturbance cap [N]")
    args = ap.parse_args(argv)
    if args.bench:
        rows = bench(args.directions, args.repeats, args.loop_repeats, args.cap)
        print(
            f"thesis 3-contact grasp, {args.directions} directions, cap {args.cap:g} N; medians of "
            f"{args.repeats} (batched) / {args.loop_repeats} (loop) interleaved runs"
        )
        print("preload  batched cold [ms]  batched warm [ms]  loop [ms]  loop/cold  max rel diff")
        for r in rows:
            print(
                f"{r['preload']:7.1f}  {r['batched_cold_ms']:17.1f}  {r['batched_warm_ms']:17.1f}"
                f"  {r['loop_ms']:9.0f}  {r['speedup_cold']:8.0f}x  {r['max_rel_diff']:12.1e}"
            )
        return
    print(f"wrote {thesis_figure(args.out, args.directions)}")


if __name__ == "__main__":
    main()
