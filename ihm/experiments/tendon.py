"""Tendon gripper holding a box (thesis ch. 5, grasp example 3): proximal vs distal tendon.

The thesis preloads its underactuated two-finger gripper (``assets/scenes/tendon_box.xml``)
in two ways with equal actuator force: only the proximal tendon active (``f_c = [F, 0]``,
the distal tendon held passively by its nonbackdrivable actuator) or only the distal one
(``f_c = [0, F]``). It predicts almost twice the resistance to a torque about the object's
x-axis (across the fingers, in the grasp plane) for the distal-only preload, and explains
it by the preload contact forces: proximal-only concentrates them on the distal links (the
proximal contacts break), distal-only loads all four links.

:func:`tendon_box` checks both claims in MuJoCo and with the stability methods:

* each case is settled with :func:`ihm.scenes.load_scene` (``nonbackdrivable=True``,
  ``seat=SEAT_N``: closed lightly with gravity off, both tendons ratcheted, then the one
  tendon loaded with ``F``); the contact forces per link and the passive tendon tensions
  (the ratchet's limit forces, :func:`passive_tensions`) are read off MuJoCo;
* predicted resistance to the torque ``(0, 0, 0, +-1, 0, 0)`` (object frame, N m) with the
  weight as base load: ``MaxDisturbance`` by ``refinement`` (an upper bound unless
  certified: its relaxation contains the exact problem) and ``iterative``;
* simulated resistance (:func:`ihm.resistance.simulated_resistance`, ratchet on): the same
  torque about the object's x-axis in world axes, ramped until the box turns 0.05 rad;
* the resistible-force map in the xy-plane for the distal-only preload (thesis fig.
  underactuated), simulated and by ``refinement``, with :func:`ihm.sim_maps.agreement`.

Outputs: ``OUT/tendon_box.csv`` (one row per number: case, method, direction, value, unit,
capped), ``OUT/tendon_box.png`` (grasp plane per case with the preload contact forces, and
the torque resistances), ``OUT/tendon_box_xy.png`` (the maps) and the summary dict that the
runner writes to ``OUT/tendon_box_summary.json``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
from numpy.typing import NDArray

from stability import Existence, solve
from stability.io import write_csv

from .. import scenes
from ..contacts import SceneGrasp, grasp_from_mujoco
from ..resistance import ResistanceOptions, simulated_resistance
from ..sim_maps import (
    MapSpec,
    agreement,
    analysis_map,
    map_value,
    scene_disturbance,
    simulated_map,
)
from . import MUJOCO_READ

__all__ = [
    "CASES",
    "FORCE_N",
    "FORCE_CAP_N",
    "SEAT_N",
    "TORQUE_CAP_NM",
    "link_normal_forces",
    "passive_tensions",
    "settle_case",
    "tendon_box",
]

SCENE = "tendon_box"
#: tendon force of the one actively loaded tendon [N]. The distal-only preload holds the
#: box only while the box's weight (0.98 N, out of the hand) balances the distal tips'
#: push toward the palm: up to about 5 N (tests/ihm/test_tendon_gripper.py); 4 N keeps a margin.
FORCE_N = 4.0
#: light closing commands (proximal, distal) [N] before the ratchet goes on (gravity off)
SEAT_N = (1.0, 0.25)
#: the two preload cases of the thesis: actively loaded tendon -> commands f_c [N]
CASES: dict[str, tuple[float, float]] = {"proximal": (FORCE_N, 0.0), "distal": (0.0, FORCE_N)}
TORQUE_CAP_NM = 1.0  # cap of the torque queries and ramps [N m] (answers are ~0.01-0.1)
FORCE_CAP_N = 10.0  # cap of the xy-plane force maps [N]
#: the simulated box "starts to turn" when it has turned this far [rad] (the resistance
#: itself is read at 0.05 rad, ihm.resistance): the load between the two is taken up by
#: the fingers following the box and the ratchets locking them there
ONSET_TURN_RAD = 1e-3
LINKS = ("left_proximal", "left_distal", "right_proximal", "right_distal")
#: the predictions with MuJoCo's stiffness (``compliance="mujoco"``), by the default 3D method
MUJOCO_LABEL = "modesearch, mujoco"


def passive_tensions(model: mujoco.MjModel, data: mujoco.MjData) -> NDArray[np.float64]:
    """Passive tendon tensions [N], one per tendon: the force of the ratchet's tendon limit
    (``mjCNSTR_LIMIT_TENDON``) at the current state, >= 0 and positive when the
    nonbackdrivable transmission holds the tendon against shortening (it then acts like a
    tension, closing the fingers). Zero for a tendon without an active limit; the tendon's
    total tension is this plus its actuator force."""
    out = np.zeros(model.ntendon)
    limit = int(mujoco.mjtConstraint.mjCNSTR_LIMIT_TENDON)
    for i in range(data.nefc):
        if data.efc_type[i] == limit:
            out[data.efc_id[i]] += data.efc_force[i]
    return out


def link_normal_forces(model: mujoco.MjModel, grasp: SceneGrasp) -> dict[str, float]:
    """Total contact normal force [N] of the hand on the object per link of
    :data:`LINKS` (0 for a link without contact)."""
    out = dict.fromkeys(LINKS, 0.0)
    for b, fn in zip(grasp.hand_bodies, grasp.forces[:, 0], strict=True):
        out[model.body(b).name] += float(fn)
    return out


def settle_case(
    commands: tuple[float, float], seat: tuple[float, float] = SEAT_N
) -> tuple[mujoco.MjModel, mujoco.MjData, SceneGrasp]:
    """``tendon_box`` settled with the thesis' protocol: seated with ``seat`` [N] (gravity
    off), both tendons ratcheted, then ``commands`` [N] with the ratchet following
    Returns the :class:`~ihm.scenes.LoadedScene` (its ``ratchet`` on the tendons) and the
    grasp read off it."""
    scene = scenes.load_scene(SCENE, commands, nonbackdrivable=True, seat=seat)
    return scene, grasp_from_mujoco(scene.model, scene.data)


def _predict(
    grasp: SceneGrasp, commands: tuple[float, float], sign: float, method: str, **opts: Any
) -> dict[str, Any]:
    """Predicted resistance [N m] to the torque ``sign * e_x`` (object frame, the wrench
    ``(0, 0, 0, sign, 0, 0)``) on top of the weight, by ``method``."""
    t0 = time.perf_counter()
    direction = np.array([0.0, 0.0, 0.0, sign, 0.0, 0.0])
    q = scene_disturbance(grasp, direction, grasp.full_commands(commands), TORQUE_CAP_NM)
    try:
        sol = solve(grasp, q, method=method, **opts)
    except Exception as exc:  # a solver error is a result too: record it, go on
        return {"value": float("nan"), "capped": False, "status": f"error: {exc}",
                "seconds": time.perf_counter() - t0}  # fmt: skip
    value, _ = map_value(sol)
    mdp = None
    if sol.forces is not None:
        try:  # the proof: how far the answer is from maximum dissipation [model units]
            mdp = float(sol.residuals().get("max_dissipation", float("nan")))
        except Exception:
            mdp = None
    return {
        "value": value,
        "capped": bool(sol.stats.get("capped", False)),
        "status": str(sol.status),
        "certified": sol.stats.get("certified"),
        "exact_value": sol.stats.get("exact_value"),
        "max_dissipation_residual": mdp,
        "seconds": time.perf_counter() - t0,
    }


def _simulate(commands: tuple[float, float], sign: float) -> dict[str, Any]:
    """Simulated resistance [N m] to a torque about the object's x-axis (world axes, the
    box's own axis as it rests), the ratchet on; a freshly settled scene per run."""
    t0 = time.perf_counter()
    scene, grasp = settle_case(commands)
    axis_world = grasp.object_mat[:, 0]
    direction = np.r_[0.0, 0.0, 0.0, sign * axis_world]
    opts = ResistanceOptions(cap=TORQUE_CAP_NM, check_rate=False, stop_rule="distance")
    res = simulated_resistance(scene.model, scene.data, direction, ratchet=scene.ratchet,
                               options=opts)  # fmt: skip
    turned = res.trace[res.trace[:, 2] > ONSET_TURN_RAD]
    onset = float(turned[0, 0]) if len(turned) else float(res.value)
    return {
        "value": float(res.value),
        "onset": onset,
        "capped": bool(res.capped),
        "turn_rad": float(res.turn),
        "shift_m": float(res.shift),
        "seconds": time.perf_counter() - t0,
    }


def _model_preload_forces(grasp: SceneGrasp, commands: tuple[float, float], opts: dict) -> Any:
    """The thesis model's preload contact forces (an equilibrium of the refinement method
    under the weight alone), (m, 3) [N]; None if it finds none."""
    try:
        sol = solve(grasp, Existence(grasp.gravity_wrench,
                                     commands=grasp.full_commands(commands)),
                    method="refinement", **opts)  # fmt: skip
    except Exception:
        return None
    if not sol.stable or sol.forces is None:
        return None
    return np.asarray(sol.forces, dtype=float).reshape(-1, 3)


def _capsule_outline(p0: NDArray, p1: NDArray, r: float, n: int = 24) -> NDArray:
    """Outline of a 2D capsule (segment p0-p1, radius r) as a closed polygon."""
    d = p1 - p0
    ang = np.arctan2(d[1], d[0])
    a1 = ang + np.linspace(np.pi / 2, 3 * np.pi / 2, n)
    a2 = ang + np.linspace(-np.pi / 2, np.pi / 2, n)
    c1 = p0 + r * np.c_[np.cos(a1), np.sin(a1)]
    c2 = p1 + r * np.c_[np.cos(a2), np.sin(a2)]
    return np.vstack([c1, c2])


def _draw_grasp(ax: Any, model: mujoco.MjModel, data: mujoco.MjData, case: dict[str, Any],
                title: str) -> None:  # fmt: skip
    """Grasp plane (world xy, mm): palm, links, box, contact points and normal-force
    arrows (MuJoCo thick blue, the thesis model's equilibrium thin red beside it)."""
    from matplotlib.patches import Polygon, Rectangle

    mm = 1000.0
    palm = model.geom("palm")
    pc, ps = data.geom_xpos[palm.id][:2] * mm, model.geom_size[palm.id][:2] * mm
    ax.add_patch(Rectangle(pc - ps, 2 * ps[0], 2 * ps[1], color="0.55", lw=0))
    for name in LINKS:
        g = model.geom(name)
        c, mat = data.geom_xpos[g.id], data.geom_xmat[g.id].reshape(3, 3)
        half = model.geom_size[g.id][1]
        p0, p1 = (c - half * mat[:, 2])[:2] * mm, (c + half * mat[:, 2])[:2] * mm
        ax.add_patch(Polygon(_capsule_outline(p0, p1, model.geom_size[g.id][0] * mm),
                             closed=True, fc="0.8", ec="0.3", lw=1))  # fmt: skip
    box = model.geom("object")
    bc, bs = data.geom_xpos[box.id], model.geom_size[box.id]
    bm = data.geom_xmat[box.id].reshape(3, 3)
    signs = ((1, 1), (-1, 1), (-1, -1), (1, -1))
    corners = [bc + bm @ (np.array([sx, sy, 0.0]) * bs) for sx, sy in signs]
    ax.add_patch(Polygon(np.array(corners)[:, :2] * mm, closed=True, fc=(0.9, 0.75, 0.5),
                         ec=(0.6, 0.4, 0.1), lw=1))  # fmt: skip
    scale = 60.0  # arrow length per force [mm/N]
    contacts = zip(case["points_mm"], case["normals"], case["fn"], strict=True)
    for k, (p, n, fn) in enumerate(contacts):
        p, n = np.asarray(p), np.asarray(n)
        side = np.array([-n[1], n[0]]) * 3.0  # the model's arrow 3 mm beside MuJoCo's
        ax.plot(*p, "o", color="k", ms=3, zorder=5)
        if fn > 0:
            ax.annotate("", xy=p, xytext=p - n * fn * scale,
                        arrowprops=dict(arrowstyle="-|>", color="C0", lw=2.2))  # fmt: skip
        model_fn = None if case["model_fn"] is None else case["model_fn"][k]
        if model_fn is not None and model_fn > 1e-6:
            ax.annotate("", xy=p + side, xytext=p + side - n * model_fn * scale,
                        arrowprops=dict(arrowstyle="-|>", color="C3", lw=1.2))  # fmt: skip
        label = f"{fn:.2f} N" + ("" if model_fn is None else f"\nmodel {model_fn:.2f} N")
        left = p[0] < 0
        if p[1] > 50:  # distal contact: above the fingertips
            off = np.array([-30.0 if left else 4.0, 13.0])
        else:
            off = np.array([-34.0 if left else 4.0, -16.0])
        ax.text(*(p + off), label, fontsize=7.5, color="C0")
    ax.set_aspect("equal")
    ax.set_xlim(-85, 85)
    ax.set_ylim(-32, 110)
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm] (out of the hand)")
    ten = case["passive_tension_N"]
    ax.set_title(title, fontsize=9)
    ax.text(-82, 102, f"tendon tension [N]: proximal {case['commands'][0] + ten[0]:.2f} "
            f"(passive {ten[0]:.2f}), distal {case['commands'][1] + ten[1]:.2f} "
            f"(passive {ten[1]:.2f})", fontsize=7)  # fmt: skip
    ax.plot([], [], color="C0", lw=2.2, label="MuJoCo normal force (60 mm/N)")
    ax.plot([], [], color="C3", lw=1.2, label="thesis model (refinement equilibrium)")
    ax.legend(loc="lower center", fontsize=7, ncol=2)


def _draw_bars(ax: Any, torque: dict[str, dict[str, dict[str, dict[str, Any]]]]) -> None:
    """Torque resistance [N m] per case and method, +x solid and -x hatched."""
    series = [
        ("sim", "value", "sim (turned 0.05 rad)"),
        ("sim", "onset", "sim onset (1 mrad)"),
        ("refinement", "value", "refinement"),
        ("iterative", "value", "iterative"),
        (MUJOCO_LABEL, "value", MUJOCO_LABEL),
    ]
    cases = list(torque)
    width = 0.8 / (2 * len(series))
    for i, case in enumerate(cases):
        for j, (method, key, _) in enumerate(series):
            for k, sign in enumerate(("+x", "-x")):
                v = torque[case][method][sign][key]
                x = i + (2 * j + k - len(series) + 0.5) * width
                h = v if np.isfinite(v) else 0.0
                ax.bar(x, h, width, color=f"C{j}", alpha=1.0 if k == 0 else 0.55,
                       hatch="" if k == 0 else "//", ec="k", lw=0.4)  # fmt: skip
                txt = "no answer" if not np.isfinite(v) else f"{v:.4f}"
                ax.text(x, h, " " + txt, ha="center", va="bottom", fontsize=6.5, rotation=90)
    for j, (method, _, label) in enumerate(series):
        residuals = [torque[c][method][s].get("max_dissipation_residual") for c in cases
                     for s in ("+x", "-x")]  # fmt: skip
        if any(r is not None and r > 1e-3 for r in residuals):
            label += " (answer violates max. dissipation)"
        ax.bar(np.nan, 0, color=f"C{j}", label=label)
    ax.bar(np.nan, 0, color="w", ec="k", hatch="//", label="-x (hatched)")
    ax.set_xticks(range(len(cases)), [f"{c} tendon only" for c in cases])
    ax.set_ylabel("resistible torque about x [N m]")
    top = max(torque[c][m][s][k] for c in cases for m, k, _ in series for s in ("+x", "-x")
              if np.isfinite(torque[c][m][s][k]))  # fmt: skip
    ax.set_ylim(0, 1.7 * top)
    ax.legend(fontsize=7, loc="upper center")
    ax.set_title("resistance to a torque about the object x-axis\n(weight as base load; "
                 "refinement: upper bound unless certified)", fontsize=9)  # fmt: skip


def _plot_xy(path: Path, sim: Any, preds: list[tuple[str, Any]], title: str) -> None:
    """The xy-plane maps (``preds``: label, map) overlaid on one polar chart with the
    simulated one; capped directions marked."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(subplot_kw={"projection": "polar"}, figsize=(6.4, 6.6))
    curves = [(rm, f"C{k + 1}", label, 8 + 2 * k) for k, (label, rm) in enumerate(preds)]
    curves.append((sim, "C0", "MuJoCo (ratcheted)", 5))
    for rm, color, label, ms in curves:
        th = np.r_[rm.angles, rm.angles[:1]]
        r = np.r_[rm.magnitudes, rm.magnitudes[:1]]
        ax.fill(th, r, color=color, alpha=0.25, lw=0)
        ax.plot(th, r, color=color, lw=1.8, marker="o", ms=3, label=label)
        if rm.capped.any():
            ax.plot(rm.angles[rm.capped], np.full(rm.capped.sum(), rm.cap), ls="none",
                    marker="^", ms=ms, color=color, mec="k",
                    label=f"{label}: held the cap ({rm.cap:g} N)")  # fmt: skip
    ax.set_ylim(0, sim.cap * 1.08)
    ax.set_title(title, fontsize=9, pad=16)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.06), fontsize=8, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _ratio(a: float, b: float) -> float:
    return float(a / b) if np.isfinite(a) and np.isfinite(b) and b > 0 else float("nan")


@dataclass(frozen=True)
class _Settings:
    """How hard a run works: refinement ``levels``, the time limits [s] of each torque
    query (``t_torque``) and of each map direction (``t_map``), and the map's number of
    ``directions``."""

    levels: int
    t_torque: float
    t_map: float
    directions: int

    @classmethod
    def of(cls, quick: bool) -> _Settings:
        """The full run's settings, or the smoke run's (``quick``)."""
        return cls(3, 20.0, 10.0, 8) if quick else cls(4, 90.0, 20.0, 36)


def _preload_case(
    commands: tuple[float, float], st: _Settings
) -> tuple[dict[str, Any], tuple[Any, Any, dict[str, Any]], SceneGrasp]:
    """One preload case settled (:func:`settle_case`): its summary entry (commands [N], the
    link normal forces [N] in MuJoCo and in the thesis model's equilibrium, the passive
    tendon tensions [N], joint angles [rad]), what :func:`_draw_grasp` draws of it (model,
    data and the case's points, normals and forces) and the grasp."""
    (model, data), grasp = settle_case(commands)
    axes_err = float(np.abs(grasp.object_mat - np.eye(3)).max())
    model_f = _model_preload_forces(grasp, commands, {"time_limit": st.t_torque,
                                                      "levels": st.levels})  # fmt: skip
    names = [model.body(b).name for b in grasp.hand_bodies]
    mf = None if model_f is None else dict.fromkeys(LINKS, 0.0)
    if mf is not None:
        for name, f in zip(names, model_f[:, 0], strict=True):
            mf[name] += float(f)
    info = {
        "commands_N": list(commands),
        "links": names,
        "normal_force_N": link_normal_forces(model, grasp),
        "model_normal_force_N": mf,
        "passive_tension_N": dict(zip(("proximal", "distal"),
                                      passive_tensions(model, data).tolist(), strict=True)),
        "joint_angles_rad": data.qpos[:4].round(5).tolist(),
        "object_axes_vs_world_max_abs": axes_err,
        "contacts": int(grasp.m),
    }  # fmt: skip
    drawn = (model, data, {
        "points_mm": (grasp.points_world()[:, :2] * 1000).tolist(),
        "normals": grasp.frames_world()[:, 0, :2].tolist(),
        "fn": grasp.forces[:, 0].tolist(),
        "model_fn": None if model_f is None else model_f[:, 0].tolist(),
        "passive_tension_N": passive_tensions(model, data).tolist(),
        "commands": list(commands),
    })  # fmt: skip
    return info, drawn, grasp


def _torque_case(
    case: str,
    grasp: SceneGrasp,
    commands: tuple[float, float],
    st: _Settings,
    rows: list[list[Any]],
) -> dict[str, dict[str, dict[str, Any]]]:
    """The resistances [N m] to the torques ``+-x`` of one case, simulated (and its onset)
    and by ``refinement`` and ``iterative`` (the thesis' unit springs) and by ``modesearch``
    with MuJoCo's stiffness (:data:`MUJOCO_LABEL`), per method and sign; one CSV row each is
    appended to ``rows``."""
    res: dict[str, dict[str, dict[str, Any]]] = {"sim": {}, "refinement": {}, "iterative": {},
                                                 MUJOCO_LABEL: {}}  # fmt: skip
    scene, _ = settle_case(commands)
    grasp_mj = grasp_from_mujoco(scene.model, scene.data, **MUJOCO_READ)
    for sign, label in ((1.0, "+x"), (-1.0, "-x")):
        res["sim"][label] = _simulate(commands, sign)
        res["refinement"][label] = _predict(grasp, commands, sign, "refinement",
                                            time_limit=st.t_torque, levels=st.levels)  # fmt: skip
        res["iterative"][label] = _predict(grasp, commands, sign, "iterative",
                                           time_limit=st.t_torque)  # fmt: skip
        res[MUJOCO_LABEL][label] = _predict(grasp_mj, commands, sign, "modesearch",
                                            time_limit=st.t_torque)  # fmt: skip
        for method in res:
            r = res[method][label]
            rows.append([case, method, f"{label} torque", r["value"], "N m", int(r["capped"])])
        r = res["sim"][label]
        rows.append([case, "sim_onset", f"{label} torque", r["onset"], "N m", 0])
    return res


def _ratios(torque: dict[str, Any]) -> dict[str, dict[str, float]]:
    """Distal / proximal resistance per method (the simulated onset as ``sim_onset``) and
    sign (thesis: about 2)."""
    ratios = {}
    for method, key in (("sim", "value"), ("sim_onset", "onset"), ("refinement", "value"),
                        ("iterative", "value"), (MUJOCO_LABEL, "value")):  # fmt: skip
        src = "sim" if method == "sim_onset" else method
        ratios[method] = {
            s: _ratio(torque["distal"][src][s][key], torque["proximal"][src][s][key])
            for s in ("+x", "-x")
        }
    return ratios


def _plot_cases(
    path: Path, drawn: dict[str, tuple[Any, Any, dict[str, Any]]], torque: dict[str, Any]
) -> None:
    """``tendon_box.png``: the grasp plane per case with its preload contact forces, and
    the torque resistances as bars."""
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(1, 3, figsize=(17, 5.6), gridspec_kw={"width_ratios": [1, 1, 0.9]})
    for ax, case in zip(axs[:2], CASES, strict=True):
        model, data, c = drawn[case]
        tag = "proximal tendon active, distal passive" if case == "proximal" else (
            "distal tendon active, proximal passive")  # fmt: skip
        _draw_grasp(ax, model, data, c, f"{tag}: f_c = {list(CASES[case])} N\n"
                    "preload contact normal forces (weight 0.98 N along +y)")  # fmt: skip
    _draw_bars(axs[2], torque)
    fig.suptitle("tendon_box (thesis grasp example 3): proximal vs distal tendon, "
                 f"F = {FORCE_N:g} N, nonbackdrivable", fontsize=11)  # fmt: skip
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _xy_map(out: Path, st: _Settings, workers: int, rows: list[list[Any]]) -> dict[str, Any]:
    """The xy-plane map of the distal-only preload (thesis fig. underactuated), simulated
    and by ``refinement`` [N]: drawn to ``tendon_box_xy.png``, one CSV row per direction
    and method appended to ``rows``; returns its summary entry."""
    commands = CASES["distal"]
    spec = MapSpec(SCENE, "xy", st.directions, preload=commands, nonbackdrivable=True,
                   seat=SEAT_N, cap=FORCE_CAP_N)  # fmt: skip
    t0 = time.perf_counter()
    sim = simulated_map(spec, workers=workers, progress=False)
    t_sim = time.perf_counter() - t0
    t0 = time.perf_counter()
    pred = analysis_map(spec, method="refinement", workers=workers, progress=False,
                        time_limit=st.t_map, levels=st.levels)  # fmt: skip
    t_pred = time.perf_counter() - t0
    t0 = time.perf_counter()
    pred_mj = analysis_map(replace(spec, **MUJOCO_READ), method="modesearch",
                           workers=workers, progress=False, time_limit=st.t_map)  # fmt: skip
    t_mj = time.perf_counter() - t0
    agree = agreement(pred, sim)
    for label, rm in (("sim", sim), ("refinement", pred), (MUJOCO_LABEL, pred_mj)):
        for a, v, c in zip(rm.angles, rm.magnitudes, rm.capped, strict=True):
            rows.append(["distal", label, f"xy {np.degrees(a):.0f} deg", float(v), "N", int(c)])
    _plot_xy(out / "tendon_box_xy.png", sim, [("refinement", pred), (MUJOCO_LABEL, pred_mj)],
             f"tendon_box, distal tendon only (F = {FORCE_N:g} N): resistible force [N] in the "
             f"xy-plane\n0 deg = +x (pushes the box into the right finger), 90 deg = +y "
             f"(out of the hand)")  # fmt: skip
    return {
        "directions": st.directions,
        "cap_N": FORCE_CAP_N,
        "angles_deg": np.degrees(sim.angles).round(2).tolist(),
        "sim_N": sim.magnitudes.tolist(),
        "sim_capped": sim.capped.tolist(),
        "refinement_N": pred.magnitudes.tolist(),
        "refinement_capped": pred.capped.tolist(),
        "agreement": agree,
        MUJOCO_LABEL + "_N": pred_mj.magnitudes.tolist(),
        MUJOCO_LABEL + "_capped": pred_mj.capped.tolist(),
        "agreement " + MUJOCO_LABEL: agreement(pred_mj, sim),
        "wall_s": {"sim": t_sim, "refinement": t_pred, MUJOCO_LABEL: t_mj},
    }


def tendon_box(out: Path, quick: bool = False, workers: int = 1) -> dict[str, Any]:
    """Run the experiment (module doc); writes ``tendon_box.csv``, ``tendon_box.png`` and
    ``tendon_box_xy.png`` into ``out`` and returns the summary.

    Parameters
    ----------
    out : output folder (created by the runner).
    quick : coarse settings for a smoke run: 8 map directions instead of 36, refinement at
        3 levels instead of 4 and shorter time limits.
    workers : processes per map (:func:`ihm.sim_maps.simulated_map`, ``analysis_map``).

    Returns
    -------
    Summary: tendon force ``F`` [N]; per case the commands [N], link normal forces [N]
    (MuJoCo and the thesis model's equilibrium), passive tendon tensions [N]; the torque
    resistances [N m] per case, method and sign with runtimes [s]; the ratios
    distal / proximal (thesis: about 2) per method; the xy-map agreement; wall times [s].
    """
    import matplotlib

    matplotlib.use("Agg")

    t_start = time.perf_counter()
    out = Path(out)
    st = _Settings.of(quick)
    rows: list[list[Any]] = []
    summary: dict[str, Any] = {
        "scene": SCENE,
        "force_N": FORCE_N,
        "seat_N": list(SEAT_N),
        "torque_cap_Nm": TORQUE_CAP_NM,
        "refinement": {"levels": st.levels, "time_limit_s": st.t_torque},
        "cases": {},
        "torque_Nm": {},
    }
    drawn: dict[str, tuple[Any, Any, dict[str, Any]]] = {}
    for case, commands in CASES.items():
        summary["cases"][case], drawn[case], grasp = _preload_case(commands, st)
        summary["torque_Nm"][case] = _torque_case(case, grasp, commands, st, rows)
    summary["ratio_distal_over_proximal"] = _ratios(summary["torque_Nm"])
    _plot_cases(out / "tendon_box.png", drawn, summary["torque_Nm"])
    t_map0 = time.perf_counter()
    summary["xy_map"] = _xy_map(out, st, workers, rows)
    summary["wall_s"] = {"torque_part": t_map0 - t_start, "total": time.perf_counter() - t_start}
    cols = ["case", "method", "direction", "value", "unit", "capped"]
    write_csv(out / "tendon_box.csv", [dict(zip(cols, r, strict=True)) for r in rows], cols)
    return summary
