"""How MuJoCo's box turns where the model with MuJoCo's stiffness reads high (the numbers of
docs/compliance.md, "What still differs"): barrett_box pushed into finger 2 without
preload, and barrett_box_3d pushed along +x with finger 2 preloaded. Per case the simulated
ramp's end, the box's motion (object frame) and rotation axis against the line through two
contacts, the turn along the ramp, and the model's least-motion equilibrium under the same
loads (``modesearch`` capped at each load). About 4 min::

    python docs/experiments/turns.py
"""

from __future__ import annotations

import mujoco
import numpy as np

import stability
from ihm.contacts import grasp_from_mujoco
from ihm.experiments import MUJOCO_READ
from ihm.experiments.barrett import _simulate, seated
from ihm.sim_maps import scene_disturbance


def rotation_vector(R0: np.ndarray, R1: np.ndarray) -> np.ndarray:
    """The rotation from ``R0`` to ``R1`` as a vector in ``R0``'s frame [rad]."""
    q, rv = np.zeros(4), np.zeros(3)
    mujoco.mju_mat2Quat(q, (R0.T @ R1).flatten())
    mujoco.mju_quat2Vel(rv, q, 1.0)
    return rv


def contact_points(m: mujoco.MjModel, d: mujoco.MjData, obj: int) -> dict[str, np.ndarray]:
    """World position [m] of each contact of the object, by the other body's name."""
    out = {}
    for c in d.contact[: d.ncon]:
        b1, b2 = m.geom_bodyid[c.geom1], m.geom_bodyid[c.geom2]
        if obj in (b1, b2):
            out[m.body(b2 if b1 == obj else b1).name] = c.pos.copy()
    return out


def case(scene: str, preload: list[float], seat: list[float], load: np.ndarray,
         pivot: tuple[str, str], loads: tuple[float, ...], cap: float) -> None:  # fmt: skip
    loaded, _ = seated(scene, preload, seat)
    (m, d), ratchet = loaded, loaded.ratchet
    obj = m.body("object").id
    R0, p0 = d.xmat[obj].reshape(3, 3).copy(), d.xipos[obj].copy()
    before = contact_points(m, d, obj)
    g = grasp_from_mujoco(m, d, **MUJOCO_READ)
    com = m.body_ipos[obj]
    wrench = np.r_[load, np.cross(com, load)]
    cmds = g.full_commands(preload)
    print(f"\n{scene}, preload {preload}, load {load} (object frame) at the centre of mass")
    for s_ in loads:
        sol = stability.solve(g, scene_disturbance(g, wrench, cmds, s_), method="modesearch",
                              time_limit=60.0)  # fmt: skip
        r = sol.motion[:6]
        print(f"  model at {s_:5.2f}: held {sol.value:.3f}, shift {np.round(r[:3] * 1e3, 3)} mm, "
              f"turn {np.linalg.norm(r[3:]):.4f} rad")  # fmt: skip
    full = stability.solve(g, scene_disturbance(g, wrench, cmds, cap), method="modesearch",
                           time_limit=60.0)  # fmt: skip
    print(f"  model's answer: {full.value:.3f} N")
    res = _simulate(m, d, ratchet, np.r_[load, 0.0, 0.0, 0.0], cap)
    rv = rotation_vector(R0, d.xmat[obj].reshape(3, 3))
    a, b = (before[name] for name in pivot)
    line = R0.T @ (b - a) / np.linalg.norm(b - a)
    angle = np.degrees(np.arccos(abs(line @ rv) / np.linalg.norm(rv)))
    arm = np.linalg.norm(np.cross(R0.T @ (p0 - a), line))
    print(f"  MuJoCo: {res.value:.3f} N ({res.reason}), shift "
          f"{np.round(R0.T @ (d.xipos[obj] - p0) * 1e3, 3)} mm, rotation vector "
          f"{np.round(rv, 4)} rad")  # fmt: skip
    moved = np.linalg.norm(rv) * arm * 1e3
    print(
        f"  axis {angle:.1f} deg from the line {pivot[0]}-{pivot[1]}, which passes "
        f"{arm * 1e3:.1f} mm from the centre of mass (turn x arm = {moved:.2f} mm)"
    )
    print(f"  touching at the end: {sorted(contact_points(m, d, obj))}")
    for s_, _, turn in res.trace[:: max(1, len(res.trace) // 12), :3]:
        print(f"    ramp {s_:6.2f} N: turn {turn:.4f} rad")


if __name__ == "__main__":
    case("barrett_box", [0.0] * 4, [0.0, 0.01, 0.01, 0.0], np.array([1.0, 0.0, 0.0]),
         ("f2_prox", "f2_dist"), (1.0, 2.0, 3.0, 3.4), 10.0)  # fmt: skip
    case("barrett_box_3d", [0.0, 0.0, 0.1, 0.0], [0.0, 0.01, 0.01, 0.022],
         np.array([1.0, 0.0, 0.0]), ("f1_prox", "f2_prox"), (10.0, 16.0, 20.0), 50.0)  # fmt: skip
