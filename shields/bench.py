"""Measurements of the QP grasp shield: ``python -m shields.bench accuracy|latency|effect``.

Each subcommand prints a table and writes ``shield_<name>.csv`` (one row per measurement),
``shield_<name>_summary.csv`` and ``shield_<name>.png`` under ``--out`` (default
``docs/bench``). Runs are deterministic for a given ``--seed``, except for the wall times of
``latency`` (the states and actions they are taken at are deterministic). The env is
``FourFingerRotate`` (sphere, gravity, torsional friction: the shipped policy's settings);
"the policy" is the shipped ``policies/four_finger_sphere``, acting deterministically on
observations normalised with its frozen ``VecNormalize`` statistics
(:func:`train.gait.load_policy`); "random" draws actions uniformly from ``[-1, 1]^12``.

``accuracy``: the linearisation against MuJoCo
------------------------------------------------
States (``--states`` of each source in ``--sources``, each with at least two finger links
touching the object):

* ``settled``: cached start grasps (drawn without replacement) after 3 zero-action steps;
* ``random``: states along random-policy rollouts, every ``--every`` steps;
* ``policy``: states along the policy's rollouts, every ``--every`` steps.

At each state ``s`` (as the env leaves it after a step: what the shield sees) the grasp is
linearised (:func:`shields.compliance.linearize`, horizon = the policy period) and the
setpoints are perturbed by ``dq``:

* ``servo``: ``dq = delta e_j`` for each servo ``j`` of a finger with a link touching the
  object and each ``delta`` in ``--deltas`` (0.01 rad and 0.05 rad = one full action);
* ``action``: ``dq = s a`` with ``s`` = 0.05 rad and ``a`` the action the source's policy
  takes at ``s`` (settled: a uniform random one): what the shield predicts in use.

The setpoints are clipped to the servos' ``ctrlrange`` as the env clips them; the prediction
uses the clipped (effective) ``dq``. From ``s`` MuJoCo then runs one policy step
(``frame_skip`` substeps, state restored with ``mj_setState``/``mjSTATE_INTEGRATION``) with
``dq``, with ``2 dq`` and with ``dq = 0``; its response is the change against the zero-action
step (which removes the creep of the state itself):

* contact forces ``dc``: each contact's ``(c_n, c_t1, c_t2, c_tau)`` in its contact frame,
  matched by hand body, against ``E dq`` [N, N m];
* object position ``dp`` [m] against ``F[:3] dq``;
* object rotation ``dtheta`` [rad], world axes: ``R(q_0) mju_subQuat(q_dq, q_0)``, against
  ``F[3:] dq``.

Relative errors ``|pred - mujoco| / |mujoco|`` (Euclidean norms; NaN when MuJoCo's change
is below 1e-12). Flags: ``same_contacts`` (the hand bodies touching the object, with
multiplicity, are the same at ``s`` and after the zero, ``dq`` and ``2 dq`` steps; otherwise
forces are compared on the bodies present in all four), ``clipped`` (a ctrlrange bound
changed ``dq`` or ``2 dq``) and ``linear`` (MuJoCo's own response is linear, as in
tests/shields/test_compliance.py: ``|dc(2 dq) - 2 dc(dq)| <= 0.1 |dc(2 dq)|``, and not clipped).
``sliding_base``: after the zero-action step some finger contact is on the friction cone (a
slip event, see ``effect``); ``starts_sliding``: after the ``dq`` or the ``2 dq`` step one is
and after the zero-action step none is. The "filtered" columns of the summary keep the
perturbations that are ``same_contacts`` and ``linear``: where a linear model can be right
at all.

``latency``: the shield's wall time per step
----------------------------------------------
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

``effect``: with and without the shield
----------------------------------------
``--episodes`` episodes of ``--steps`` steps (400 = 20 s) per agent (``random``,
``policy``), each without a shield and with ``shields.GraspShield`` (DAQP), episode ``i``
from the same start grasp in both (``env.reset(seed=seed + i)``; the random agent's action
stream is seeded with ``(seed, i)`` too). A drop ends an episode. Per episode: dropped;
rotation speed = turned angle about +z / episode time [rad/s] (as
``train.rotate.evaluate_rotation``); slip events; contact losses; shield interventions
(``info["shield_intervened"]``: statuses ``corrected`` and ``fallback``), status counts and
``|a~ - clip(a)|`` (mean over shielded steps); ``steps_outside``: shielded steps at whose
start some touching link was already outside its constraints (``latency``,
``links_outside``). Summary per agent and shield: drop rate with its Wilson 95 % interval
(:func:`train.stats.wilson_interval`), means with t-based 95 % intervals over episodes, and
the paired speed difference (shield - none).

*Slip event*: a policy step at whose end some contact of a finger link (the observed links
``envs.four_finger.CONTACT_LINKS``; palm and floor excluded) with the object has its force on
the surface of MuJoCo's friction cone: with ``f`` the contact's ``efc_force`` rows (``f_0``
the normal force, ``f_1, f_2`` tangential, ``f_3`` the torsional moment of a ``condim`` 4
contact) and ``mu_j = contact.friction[j - 1]``, ``sqrt(sum_j (f_j / mu_j)^2) / f_0 >= 0.99``
(counted once per step however many contacts slip). MuJoCo's ``efc_state ==
mjCNSTRSTATE_CONE`` is not used: the constant exists in MuJoCo 4.0, but with the env's PGS
(dual) solver ``efc_state`` is set by ``dualState`` (``src/engine/engine_solver.c``), which
labels a force exactly on the cone surface (PGS projects a sliding contact's friction onto
the ellipsoid: the ratio is 1 to 1e-9) ``CONE`` or ``SATISFIED`` depending on round-off: in
the default run only 10-13 % of the finger contacts with a ratio >= 0.99 were labelled
``CONE``. The per-episode CSV reports both counts (``slip_contacts``,
``slip_contacts_cone_state``). "End of a step" is the contact data the env leaves after the
step (the last substep's collision detection, as in the observation). *Contact loss*: a
finger link that touched the object at the start of a step and does not at its end
(counted per link).

Absolute latencies measured on a loaded machine are not final numbers; the ratio between the
backends is the more robust one.
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
import time
from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
from numpy.typing import NDArray
from tqdm import tqdm

from envs.four_finger import CONTACT_LINKS, FourFingerRotate
from ihm.contacts import body_subtree
from ihm.hands.four_finger import ACTUATOR_NAMES
from shields.compliance import GraspLinearization, linearize
from shields.qp import BACKENDS, STATUSES, GraspQP, ShieldLimits
from shields.wrappers import GraspShield

__all__ = [
    "AGENTS",
    "SLIP_RATIO",
    "SOURCES",
    "AccuracyState",
    "accuracy_states",
    "build_parser",
    "cone_ratios",
    "links_outside",
    "main",
    "plot_accuracy",
    "plot_effect",
    "plot_latency",
    "run_accuracy",
    "run_effect",
    "run_episode",
    "run_latency",
    "summarize_accuracy",
    "summarize_effect",
    "summarize_latency",
]

SOURCES = ("settled", "random", "policy")
AGENTS = ("random", "policy")
SLIP_RATIO = 0.99  # cone ratio at and above which a contact slips (on the cone surface)
SPEC = mujoco.mjtState.mjSTATE_INTEGRATION
_MIN_CHANGE = 1e-12  # MuJoCo changes below this are "none": no relative error
Policy = Callable[[NDArray[np.float32]], NDArray[np.float32]]


# -- shared ---------------------------------------------------------------------------------
def _policy(threads: int = 1) -> tuple[Policy, dict[str, Any]]:
    """The shipped policy (deterministic, with its observation normalisation) and its env
    options. ``train`` is imported here, lazily: this is a leaf CLI, as envs.bench."""
    import torch

    from train.gait import SHIPPED, load_policy

    torch.set_num_threads(threads)
    return load_policy(SHIPPED)


def _make_env(opts: dict[str, Any] | None = None) -> FourFingerRotate:
    return FourFingerRotate(**(opts or {}))


def _object_qpos(model: mujoco.MjModel) -> int:
    return int(model.jnt_qposadr[model.joint("object").id])


class _Links:
    """The finger-link/object contacts of a model's data (links: ``CONTACT_LINKS``)."""

    def __init__(self, model: mujoco.MjModel) -> None:
        self.link_of_body = {model.body(n).id: k for k, n in enumerate(CONTACT_LINKS)}
        in_obj = body_subtree(model, model.body("object").id)
        self.geom_obj = in_obj[model.geom_bodyid].tolist()
        self.geom_link = [self.link_of_body.get(int(b), -1) for b in model.geom_bodyid]

    def contacts(self, data: mujoco.MjData) -> list[tuple[int, int]]:
        """``(link index, contact index)`` of every active finger-link/object contact."""
        out = []
        if data.ncon == 0:
            return out
        c = data.contact
        for i, ((g1, g2), adr, ex) in enumerate(
            zip(c.geom.tolist(), c.efc_address.tolist(), c.exclude.tolist(), strict=True)
        ):
            if adr < 0 or ex:
                continue
            if self.geom_obj[g1] and not self.geom_obj[g2]:
                k = self.geom_link[g2]
            elif self.geom_obj[g2] and not self.geom_obj[g1]:
                k = self.geom_link[g1]
            else:
                continue
            if k >= 0:
                out.append((k, i))
        return out

    def touching(self, data: mujoco.MjData) -> set[int]:
        """Indices (into CONTACT_LINKS) of the finger links touching the object."""
        return {k for k, _ in self.contacts(data)}


def cone_ratios(data: mujoco.MjData, contact_ids: Sequence[int]) -> NDArray[np.float64]:
    """``sqrt(sum_j (f_j / mu_j)^2) / f_0`` of each contact (module docstring, slip event):
    1 on the surface of MuJoCo's elliptic friction cone, < 1 inside; 0 for ``f_0 <= 0``."""
    out = np.zeros(len(contact_ids))
    ef = data.efc_force
    for n, i in enumerate(contact_ids):
        con = data.contact[i]
        a, dim = int(con.efc_address), int(con.dim)
        f0 = ef[a]
        if f0 <= 0 or dim < 2:
            continue
        out[n] = float(np.linalg.norm(ef[a + 1 : a + dim] / con.friction[: dim - 1])) / f0
    return out


def links_outside(prob: Any) -> int:
    """Touching links of a :class:`shields.qp.ShieldProblem` whose contacts already
    violate their rows at the zero action: a normal force below ``c_min`` or a force outside
    the inscribed friction pyramid (a contact sliding on MuJoCo's cone is outside it)."""
    if prob is None or not prob.groups:
        return 0
    bad = prob.low_contact.max(axis=1) > 1e-6
    return sum(bool(bad[g].any()) for g in prob.groups)


def _quantiles(x: Sequence[float] | NDArray, qs: Sequence[float]) -> list[float]:
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    if len(x) == 0:
        return [math.nan] * len(qs)
    return [float(v) for v in np.percentile(x, [100 * q for q in qs])]


def _write_csv(path: Path, rows: list[dict[str, Any]]) -> None:
    fields = list(dict.fromkeys(k for r in rows for k in r))
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields)
        w.writeheader()
        for r in rows:
            w.writerow({k: f"{v:.6g}" if isinstance(v, float) else v for k, v in r.items()})


def _fmt(v: Any, nd: int = 3) -> str:
    if isinstance(v, float):
        return "nan" if not np.isfinite(v) else f"{v:.{nd}g}" if abs(v) < 1e-3 else f"{v:.{nd}f}"
    return str(v)


def _print_table(rows: list[dict[str, Any]], cols: Sequence[str], nd: int = 3) -> None:
    cells = [[_fmt(r.get(c, ""), nd) for c in cols] for r in rows]
    widths = [max(len(c), *(len(row[j]) for row in cells)) for j, c in enumerate(cols)]
    print("  ".join(c.rjust(w) for c, w in zip(cols, widths, strict=True)))
    for row in cells:
        print("  ".join(v.rjust(w) for v, w in zip(row, widths, strict=True)))


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


# -- accuracy --------------------------------------------------------------------------------
@dataclass
class AccuracyState:
    """A state to perturb: where it came from, its MuJoCo state, linearisation and the
    action its source's policy takes there."""

    source: str
    index: int  # the cached grasp (settled) or the rollout
    step: int  # steps since the reset
    state: NDArray[np.float64]
    lin: GraspLinearization
    actions: list[NDArray[np.float64]]


def accuracy_states(
    env: FourFingerRotate,
    source: str,
    n: int,
    seed: int,
    *,
    every: int = 3,
    act: Policy | None = None,
    actions: int = 1,
    max_rollouts: int = 500,
) -> Iterator[AccuracyState]:
    """``n`` states of ``source`` (module docstring) with at least two finger links touching
    the object. Rollout ``r`` of the ``random``/``policy`` sources starts from the grasp drawn
    with reset seed ``1000 seed + r`` and yields its state every ``every`` steps until it
    drops or reaches 60 steps. Each state carries the action its policy takes there (the
    rollout continues with it) and, without ``act``, ``actions - 1`` more uniform draws.
    Raises ``RuntimeError`` when ``max_rollouts`` rollouts do not give ``n`` states."""
    m, d = env.model, env.data
    links = _Links(m)
    rng = np.random.default_rng([seed, SOURCES.index(source)])
    size = mujoco.mj_stateSize(m, SPEC)

    def capture(index: int, step: int, action: NDArray) -> AccuracyState:
        s = np.empty(size)
        mujoco.mj_getState(m, d, s, SPEC)
        lin = linearize(m, d, horizon=env.dt)
        acts = [np.asarray(action, dtype=np.float64)]
        if act is None:
            acts += [rng.uniform(-1.0, 1.0, 12) for _ in range(actions - 1)]
        return AccuracyState(source, index, step, s, lin, acts)

    if source == "settled":
        grasps = rng.permutation(len(env.grasps))
        got = 0
        for g in grasps:
            env.reset(options={"grasp": int(g)})
            for _ in range(3):
                env.step(np.zeros(12, dtype=np.float32))
            if len(links.touching(d)) < 2:
                continue
            yield capture(int(g), 3, rng.uniform(-1.0, 1.0, 12))
            got += 1
            if got == n:
                return
        raise RuntimeError(f"only {got} of {n} settled grasps have two links touching")
    if source not in ("random", "policy"):
        raise ValueError(f"unknown source {source!r}; choose one of {SOURCES}")
    if source == "policy" and act is None:
        raise ValueError("source 'policy' needs act")
    got = 0
    for r in range(max_rollouts):
        obs, _ = env.reset(seed=1000 * seed + r)
        for t in range(1, 61):
            a = rng.uniform(-1.0, 1.0, 12) if act is None else np.asarray(act(obs), float)
            if t % every == 0 and len(links.touching(d)) >= 2:
                yield capture(r, t - 1, a)
                got += 1
                if got == n:
                    return
            obs, _, term, _, _ = env.step(a.astype(np.float32))
            if term:
                break
    raise RuntimeError(f"only {got} of {n} {source} states in {max_rollouts} rollouts")


@dataclass
class _Response:
    """MuJoCo's state one policy step after a setpoint change (:func:`_respond`)."""

    forces: dict[int, NDArray]  # hand body id -> its contacts' forces (k, nc) [N, N m]
    pos: NDArray  # object position [m]
    quat: NDArray  # object orientation (wxyz)
    dq: NDArray  # the effective setpoint change (after the ctrlrange clip) [rad]
    sliding: bool  # some hand-link/object contact on the friction cone (slip event)


def _respond(env: FourFingerRotate, state: NDArray, dq: NDArray, qadr: int) -> _Response:
    """One policy step from ``state`` with the setpoints moved by ``dq`` (clipped to the
    ctrlrange)."""
    m, d = env.model, env.data
    mujoco.mj_setState(m, d, state, SPEC)
    mujoco.mj_forward(m, d)
    rng_ = m.actuator_ctrlrange
    ctrl0 = d.ctrl.copy()
    d.ctrl[:] = np.minimum(np.maximum(ctrl0 + dq, rng_[:, 0]), rng_[:, 1])
    eff = d.ctrl - ctrl0
    mujoco.mj_step(m, d, nstep=env.frame_skip)
    lin = linearize(m, d, horizon=env.dt)
    hand = m.body_weldid[lin.bodies] != 0
    ratios = cone_ratios(d, lin.contact_ids[hand].tolist())
    return _Response(
        _by_body(lin),
        d.qpos[qadr : qadr + 3].copy(),
        d.qpos[qadr + 3 : qadr + 7].copy(),
        eff,
        bool(np.any(ratios >= SLIP_RATIO)),
    )


def _by_body(lin: GraspLinearization, values: NDArray | None = None) -> dict[int, NDArray]:
    """Hand body id -> its contacts' rows of ``values`` (default: the forces), in contact
    order."""
    v = lin.forces if values is None else values
    out: dict[int, list[NDArray]] = {}
    for k, b in enumerate(lin.bodies.tolist()):
        out.setdefault(b, []).append(v[k])
    return {b: np.array(rows) for b, rows in out.items()}


def _shape(c: dict[int, NDArray]) -> dict[int, int]:
    return {b: len(v) for b, v in c.items()}


def _rel(pred: NDArray, meas: NDArray) -> float:
    den = float(np.linalg.norm(meas))
    if den < _MIN_CHANGE:
        return math.nan
    return float(np.linalg.norm(pred - meas)) / den


def _rot(q1: NDArray, q0: NDArray) -> NDArray:
    """World rotation vector taking ``q0`` to ``q1`` [rad]."""
    r = np.zeros(3)
    mujoco.mju_subQuat(r, q1, q0)
    R = np.zeros(9)
    mujoco.mju_quat2Mat(R, q0)
    return R.reshape(3, 3) @ r


def _perturb(
    env: FourFingerRotate, st: AccuracyState, dq: NDArray, base: _Response, qadr: int
) -> dict[str, Any]:
    """Compare MuJoCo's response to ``dq`` at ``st`` with the linearisation's prediction
    (module docstring); ``base`` is :func:`_respond` with ``dq = 0``."""
    r0 = base
    r1 = _respond(env, st.state, dq, qadr)
    r2 = _respond(env, st.state, 2 * dq, qadr)
    c0, c1, c2 = r0.forces, r1.forces, r2.forces
    p0, q0, p1, q1 = r0.pos, r0.quat, r1.pos, r1.quat
    eff1, eff2 = r1.dq, r2.dq
    lin = st.lin
    clipped = bool(np.abs(eff1 - dq).max() > 1e-12 or np.abs(eff2 - 2 * dq).max() > 1e-12)
    pred_c = _by_body(lin, (lin.E @ eff1).reshape(lin.m, -1))
    s0 = _shape(_by_body(lin))
    same = s0 == _shape(c0) == _shape(c1) == _shape(c2)
    common = [b for b in pred_c if all(b in c and len(c[b]) == s0[b] for c in (c0, c1, c2))]
    if common:
        dc1 = np.concatenate([(c1[b] - c0[b]).ravel() for b in common])
        dc2 = np.concatenate([(c2[b] - c0[b]).ravel() for b in common])
        pc = np.concatenate([pred_c[b].ravel() for b in common])
        err_c = _rel(pc, dc1)
        nonlin = float(np.linalg.norm(dc2 - 2 * dc1)) / max(float(np.linalg.norm(dc2)), 1e-300)
    else:
        dc1 = np.zeros(0)
        err_c, nonlin = math.nan, math.nan
    du = lin.F @ eff1
    dp = p1 - p0
    dth = _rot(q1, q0)
    return {
        "same_contacts": bool(same),
        "clipped": clipped,
        "nonlinearity": nonlin,
        "linear": bool(not clipped and np.isfinite(nonlin) and nonlin <= 0.1),
        "sliding_base": r0.sliding,
        "starts_sliding": bool((r1.sliding or r2.sliding) and not r0.sliding),
        "contacts": lin.m,
        "links": len(s0),
        "dq_norm_rad": float(np.linalg.norm(eff1)),
        "dc_norm": float(np.linalg.norm(dc1)),
        "dp_norm_m": float(np.linalg.norm(dp)),
        "dtheta_norm_rad": float(np.linalg.norm(dth)),
        "err_force": err_c,
        "err_pos": _rel(du[:3], dp),
        "err_rot": _rel(du[3:], dth),
    }


def run_accuracy(
    out: Path,
    *,
    seed: int = 0,
    states: int = 20,
    deltas: Sequence[float] = (0.01, 0.05),
    sources: Sequence[str] = SOURCES,
    every: int = 3,
    actions: int = 4,
    progress: bool = True,
) -> list[dict[str, Any]]:
    """The ``accuracy`` measurement (module docstring): one row per perturbation, written to
    ``out/shield_accuracy.csv``; summary to ``shield_accuracy_summary.csv``; chart
    ``shield_accuracy.png``. Returns the rows."""
    act, opts = _policy() if "policy" in sources else (None, {})
    env = _make_env(opts)
    qadr = _object_qpos(env.model)
    rows: list[dict[str, Any]] = []
    fingers_of = {n: int(n[1]) - 1 for n in CONTACT_LINKS}
    bar = tqdm(total=states * len(sources), desc="accuracy states", disable=not progress)
    for source in sources:
        src_act = act if source == "policy" else None
        gen = accuracy_states(env, source, states, seed, every=every, act=src_act, actions=actions)
        for st in gen:
            base = _respond(env, st.state, np.zeros(12), qadr)
            fingers = sorted({fingers_of[n] for n in st.lin.links if n in fingers_of})
            jobs: list[tuple[str, float, int, NDArray]] = []
            for delta in deltas:
                for f in fingers:
                    for j in range(3 * f, 3 * f + 3):
                        dq = np.zeros(12)
                        dq[j] = delta
                        jobs.append(("servo", float(delta), j, dq))
            for a in st.actions:
                dq = env.max_setpoint_step * np.clip(a, -1.0, 1.0)
                jobs.append(("action", env.max_setpoint_step, -1, dq))
            for kind, delta, j, dq in jobs:
                row = {
                    "source": source,
                    "grasp_or_rollout": st.index,
                    "step": st.step,
                    "kind": kind,
                    "delta_rad": delta,
                    "servo": ACTUATOR_NAMES[j] if j >= 0 else "all",
                }
                row.update(_perturb(env, st, dq, base, qadr))
                rows.append(row)
            bar.update()
    bar.close()
    env.close()
    _save(out, "shield_accuracy", rows, summarize_accuracy, plot_accuracy)
    return rows


def _group(row: dict[str, Any]) -> str:
    if row["kind"] == "action":
        return "action 0.05 a"
    return f"servo {row['delta_rad']:g} rad"


def summarize_accuracy(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per (source, perturbation group): count, share linear / same contacts, median and
    90th percentile of each relative error, all and filtered (same contacts and linear)."""
    keys = list(dict.fromkeys((r["source"], _group(r)) for r in rows))
    out = []
    for source, group in keys:
        sel = [r for r in rows if r["source"] == source and _group(r) == group]
        filt = [r for r in sel if r["same_contacts"] and r["linear"]]
        s: dict[str, Any] = {"source": source, "perturbation": group, "n": len(sel)}
        s["same_contacts"] = float(np.mean([r["same_contacts"] for r in sel]))
        s["linear"] = float(np.mean([r["linear"] for r in sel]))
        s["sliding_base"] = float(np.mean([r["sliding_base"] for r in sel]))
        s["starts_sliding"] = float(np.mean([r["starts_sliding"] for r in sel]))
        s["n_filtered"] = len(filt)
        for name in ("force", "pos", "rot"):
            for tag, rs in (("", sel), ("filt_", filt)):
                med, p90 = _quantiles([r[f"err_{name}"] for r in rs], (0.5, 0.9))
                s[f"{tag}{name}_med"] = med
                s[f"{tag}{name}_p90"] = p90
        out.append(s)
    return out


def plot_accuracy(rows: list[dict[str, Any]], path: Path) -> None:
    """CDFs of the relative errors (log x): rows of panels = state sources, columns = contact
    forces, object position, object rotation; one colour per perturbation group, solid over
    all perturbations, dashed over the filtered ones (same contacts, MuJoCo linear)."""
    plt = _pyplot()
    sources = [s for s in SOURCES if any(r["source"] == s for r in rows)]
    groups = list(dict.fromkeys(_group(r) for r in rows))
    quantities = (
        ("force", "contact forces"),
        ("pos", "object position"),
        ("rot", "object rotation"),
    )
    fig, axes = plt.subplots(
        len(sources), 3, figsize=(13.5, 3.4 * len(sources)), sharex=True, sharey=True, squeeze=False
    )
    for i, source in enumerate(sources):
        for ax, (name, label) in zip(axes[i], quantities, strict=True):
            for g, group in enumerate(groups):
                sel = [r for r in rows if r["source"] == source and _group(r) == group]
                for filtered in (False, True):
                    rs = [r for r in sel if r["same_contacts"] and r["linear"]] if filtered else sel
                    x = np.sort(np.asarray([r[f"err_{name}"] for r in rs], dtype=float))
                    x = x[np.isfinite(x)]
                    if len(x) == 0:
                        continue
                    ax.plot(
                        np.maximum(x, 1e-3), np.arange(1, len(x) + 1) / len(x),
                        color=f"C{g}", ls="--" if filtered else "-", lw=1.0 if filtered else 1.8,
                        label=f"{group}, {'filtered' if filtered else 'all'} (n={len(x)})",
                    )  # fmt: skip
            ax.axvline(1.0, color="gray", lw=0.8)
            ax.set_xscale("log")
            ax.grid(alpha=0.3, which="both")
            ax.set_title(f"{source} states: {label}", fontsize=10)
            if i == len(sources) - 1:
                ax.set_xlabel("relative error |prediction - MuJoCo| / |MuJoCo|")
        axes[i, 0].set_ylabel("fraction of perturbations")
        axes[i, 0].legend(fontsize=7, loc="upper left")
    fig.suptitle(
        "Linearised grasp (E dq, F dq) vs MuJoCo one policy step after a setpoint change dq "
        "(CDFs; 1 = the error of predicting no change)"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _print_accuracy(summary: list[dict[str, Any]]) -> None:
    print("\nrelative errors of the linearised prediction (median / p90), all perturbations:")
    cols = ["source", "perturbation", "n", "same_contacts", "linear", "sliding_base"]
    cols += ["starts_sliding"]
    cols += ["force_med", "force_p90", "pos_med", "pos_p90", "rot_med", "rot_p90"]
    _print_table(summary, cols, 2)
    print("\nfiltered (same contacts and MuJoCo linear):")
    cols = ["source", "perturbation", "n_filtered"]
    cols += [f"filt_{n}_{q}" for n in ("force", "pos", "rot") for q in ("med", "p90")]
    _print_table(summary, cols, 2)


# -- latency ---------------------------------------------------------------------------------
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
    act, opts = _policy() if "policy" in sources else (None, {})
    env = _make_env(opts)
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
    _save(out, "shield_latency", rows, summarize_latency, plot_latency)
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
            med, p95 = _quantiles([1e3 * r["solve_time_s"] for r in sel], (0.5, 0.95))
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
    med, mx = _quantiles(both, (0.5, 1.0))
    out.append(
        {"backend": "osqp vs daqp", "by": "agreement", "group": "states", "calls": len(pairs),
         "status_differs": differ, "action_diff_med": med, "action_diff_max": mx}
    )  # fmt: skip
    for tag, solved in (("all states", False), ("states with QPs", True)):
        ratio = _state_ratios(rows, solved)
        med, p5, p95 = _quantiles(ratio, (0.5, 0.05, 0.95))
        out.append(
            {"backend": "osqp/daqp", "by": "ratio", "group": tag, "calls": len(ratio),
             "median_ms": med, "p95_ms": p95, "p05": p5}
        )  # fmt: skip
    return out


def plot_latency(rows: list[dict[str, Any]], path: Path) -> None:
    """Box plots of the wall time per backend by touching links and by status (log y),
    and the histogram of the per-state osqp/daqp ratio."""
    plt = _pyplot()
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
    _print_table(rows, cols, 3)
    for s in summary:
        if s["by"] == "agreement":
            print(
                f"backends at the same state: statuses differ at {s['status_differs']} of "
                f"{s['calls']} states; |a_daqp - a_osqp| where both corrected: median "
                f"{_fmt(s['action_diff_med'], 2)}, max {_fmt(s['action_diff_max'], 2)}"
            )
    ratio = {s["group"]: s for s in summary if s["by"] == "ratio"}
    for tag, s in ratio.items():
        print(
            f"osqp/daqp per state, {tag}: median {_fmt(s['median_ms'], 2)} "
            f"(5-95 %: {_fmt(s['p05'], 2)}-{_fmt(s['p95_ms'], 2)}, {s['calls']} states)"
        )
    r = ratio.get("all states", {}).get("median_ms", math.nan)
    if np.isfinite(r):
        faster, x = ("daqp", r) if r >= 1 else ("osqp", 1 / r)
        print(f"faster: {faster} (x{x:.2f} per state, median)")


# -- effect ----------------------------------------------------------------------------------
def run_episode(
    env: FourFingerRotate | GraspShield,
    act: Policy | None,
    *,
    seed: int,
    action_seed: Sequence[int],
    steps: int,
) -> dict[str, Any]:
    """One episode from the grasp of ``env.reset(seed=seed)`` (``act`` None: uniform random
    actions from ``default_rng(action_seed)``); the per-episode metrics of the module
    docstring."""
    base = env.unwrapped
    m, d, dt = base.model, base.data, float(base.dt)
    links = _Links(m)
    cone = int(mujoco.mjtConstraintState.mjCNSTRSTATE_CONE)
    rng = np.random.default_rng(list(action_seed))
    obs, info = env.reset(seed=seed)
    grasp = int(info["grasp"])
    before = links.touching(d)
    n = slips = slip_contacts = slip_cone = losses = interventions = outside = 0
    qp = env.qp if isinstance(env, GraspShield) else None
    corrections: list[float] = []
    statuses: Counter[str] = Counter()
    term = False
    angle = 0.0
    for _ in range(steps):
        a = rng.uniform(-1.0, 1.0, 12) if act is None else act(obs)
        obs, _, term, trunc, info = env.step(np.asarray(a, dtype=np.float32))
        n += 1
        angle = float(info["rotation_angle"])
        cs = links.contacts(d)
        after = {k for k, _ in cs}
        losses += len(before - after)
        before = after
        ratios = cone_ratios(d, [i for _, i in cs])
        slipping = [i for (_, i), r in zip(cs, ratios, strict=True) if r >= SLIP_RATIO]
        slips += bool(slipping)
        slip_contacts += len(slipping)
        slip_cone += sum(int(d.efc_state[d.contact[i].efc_address]) == cone for i in slipping)
        if "shield_status" in info:
            statuses[info["shield_status"]] += 1
            interventions += bool(info["shield_intervened"])
            if qp is not None and links_outside(qp.last_problem) > 0:
                outside += 1
            corrections.append(float(info["shield_correction"]))
        if term or trunc:
            break
    row: dict[str, Any] = {
        "seed": seed,
        "grasp": grasp,
        "steps": n,
        "dropped": bool(term),
        "speed_rad_s": angle / (n * dt),
        "slip_events": slips,
        "slip_contacts": slip_contacts,
        "slip_contacts_cone_state": slip_cone,
        "contact_losses": losses,
        "interventions": interventions,
        "steps_outside": outside,
        "mean_correction": float(np.mean(corrections)) if corrections else 0.0,
    }
    row.update({s: statuses.get(s, 0) for s in STATUSES})
    return row


def effect_name(relax_contacts: bool, soft_closure: bool) -> str:
    """File stem of an ``effect`` run: ``shield_effect[_relaxed][_soft]``."""
    return "shield_effect" + "_relaxed" * relax_contacts + "_soft" * soft_closure


def _save(
    out: Path,
    name: str,
    rows: list[dict[str, Any]],
    summarize: Callable[[list[dict[str, Any]]], list[dict[str, Any]]],
    plot: Callable[[list[dict[str, Any]], Path], Any],
    plot_summary: bool = False,
) -> None:
    """``out/<name>.csv`` (rows), ``<name>_summary.csv`` and ``<name>.png`` (the chart of
    the rows, or of the summary with ``plot_summary``)."""
    out.mkdir(parents=True, exist_ok=True)
    _write_csv(out / f"{name}.csv", rows)
    summary = summarize(rows)
    _write_csv(out / f"{name}_summary.csv", summary)
    plot(summary if plot_summary else rows, out / f"{name}.png")


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
        act, opts = _policy() if agent == "policy" else (None, {})
        bare = _make_env(opts)
        shielded = GraspShield(_make_env(opts), backend="daqp", limits=limits)
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
    _save(out, name, rows, summarize_effect, plot_effect, plot_summary=True)
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
    from train.stats import wilson_interval

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
    plt = _pyplot()
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
    _print_table(table, list(table[0]) if table else [])
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


# -- command line ----------------------------------------------------------------------------
def _csv_list(kind: type, choices: Sequence[Any] | None = None) -> Callable[[str], list[Any]]:
    def parse(text: str) -> list[Any]:
        try:
            values = [kind(v) for v in text.split(",") if v]
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
        if not values:
            raise argparse.ArgumentTypeError("empty list")
        if choices is not None and any(v not in choices for v in values):
            raise argparse.ArgumentTypeError(f"choose from {', '.join(map(str, choices))}")
        return values

    return parse


def _positive(text: str) -> int:
    v = int(text)
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {v}")
    return v


def build_parser() -> argparse.ArgumentParser:
    """The command line (subcommands ``accuracy``, ``latency``, ``effect``)."""
    p = argparse.ArgumentParser(
        prog="python -m shields.bench", description=(__doc__ or "").split("\n\n")[0]
    )
    sub = p.add_subparsers(dest="command", required=True)
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--out", default="docs/bench", help="directory for the CSV and PNG")
    common.add_argument("--seed", type=int, default=0, help="seed of states, actions, grasps")
    common.add_argument("--no-progress", action="store_true", help="no progress bar")
    fmt = argparse.ArgumentDefaultsHelpFormatter
    a = sub.add_parser(
        "accuracy", parents=[common], help="linearisation vs MuJoCo", formatter_class=fmt
    )
    a.add_argument("--states", type=_positive, default=20, help="states per source")
    a.add_argument("--sources", type=_csv_list(str, SOURCES), default=list(SOURCES),
                   help="comma-separated state sources: settled,random,policy")  # fmt: skip
    a.add_argument("--deltas", type=_csv_list(float), default=[0.01, 0.05],
                   help="single-servo setpoint changes [rad], comma-separated")  # fmt: skip
    a.add_argument("--every", type=_positive, default=3, help="rollout steps between states")
    a.add_argument("--actions", type=_positive, default=4,
                   help="whole-action perturbations per state (policy states: 1)")  # fmt: skip
    lat = sub.add_parser(
        "latency", parents=[common], help="shield wall time per backend", formatter_class=fmt
    )
    lat.add_argument("--episodes", type=_positive, default=4, help="rollouts per source")
    lat.add_argument("--steps", type=_positive, default=100, help="steps per rollout")
    lat.add_argument("--repeats", type=_positive, default=2, help="calls per backend and state")
    lat.add_argument("--sources", type=_csv_list(str, AGENTS), default=list(AGENTS),
                     help="comma-separated: random,policy")  # fmt: skip
    e = sub.add_parser(
        "effect", parents=[common], help="with vs without the shield", formatter_class=fmt
    )
    e.add_argument("--episodes", type=_positive, default=40, help="paired episodes per agent")
    e.add_argument("--steps", type=_positive, default=400, help="steps per episode (20 Hz)")
    e.add_argument("--agents", type=_csv_list(str, AGENTS), default=list(AGENTS),
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
    return p


def main(argv: Sequence[str] | None = None) -> list[dict[str, Any]]:
    """Run one subcommand; print its table; return its summary rows."""
    args = build_parser().parse_args(argv)
    out = Path(args.out)
    progress = not args.no_progress
    t0 = time.perf_counter()
    if args.command == "accuracy":
        if any(not (np.isfinite(x) and x > 0) for x in args.deltas):
            raise SystemExit("--deltas must be finite numbers > 0 [rad]")
        rows = run_accuracy(
            out, seed=args.seed, states=args.states, deltas=args.deltas,
            sources=args.sources, every=args.every, actions=args.actions, progress=progress,
        )  # fmt: skip
        summary = summarize_accuracy(rows)
        _print_accuracy(summary)
        names = ("shield_accuracy.csv", "shield_accuracy_summary.csv", "shield_accuracy.png")
    elif args.command == "latency":
        rows = run_latency(
            out, seed=args.seed, episodes=args.episodes, steps=args.steps,
            repeats=args.repeats, sources=args.sources, progress=progress,
        )  # fmt: skip
        summary = summarize_latency(rows)
        _print_latency(summary)
        names = ("shield_latency.csv", "shield_latency_summary.csv", "shield_latency.png")
    else:
        rows = run_effect(
            out, seed=args.seed, episodes=args.episodes, steps=args.steps,
            agents=args.agents, progress=progress, relax_contacts=args.relax_contacts,
            soft_closure=args.soft_closure,
        )  # fmt: skip
        summary = summarize_effect(rows)
        _print_effect(summary)
        stem = effect_name(args.relax_contacts, args.soft_closure)
        names = (f"{stem}.csv", f"{stem}_summary.csv", f"{stem}.png")
    print(f"wrote {', '.join(str(out / n) for n in names)} ({time.perf_counter() - t0:.0f} s)")
    return summary


if __name__ == "__main__":
    main(sys.argv[1:])
