"""The QP shield's linearisation against MuJoCo: ``python -m train.bench shield accuracy``.

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

Common options, files and the slip event: :mod:`train.bench.shield_common`.
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
from numpy.typing import NDArray
from tqdm import tqdm

from envs.four_finger import CONTACT_LINKS, FourFingerRotate
from ihm.hands.four_finger import ACTUATOR_NAMES
from shields.compliance import GraspLinearization, linearize
from train.bench.shield_common import (
    SLIP_RATIO,
    Links,
    Policy,
    cone_ratios,
    csv_list,
    make_env,
    positive,
    print_table,
    pyplot,
    quantiles,
    save,
    shipped_policy,
    wrote,
)

__all__ = [
    "SOURCES",
    "AccuracyState",
    "accuracy_states",
    "add_parser",
    "plot_accuracy",
    "run",
    "run_accuracy",
    "summarize_accuracy",
]

SOURCES = ("settled", "random", "policy")
SPEC = mujoco.mjtState.mjSTATE_INTEGRATION
_MIN_CHANGE = 1e-12  # MuJoCo changes below this are "none": no relative error


def _object_qpos(model: mujoco.MjModel) -> int:
    return int(model.jnt_qposadr[model.joint("object").id])


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
    links = Links(m)
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
    act, opts = shipped_policy() if "policy" in sources else (None, {})
    env = make_env(opts)
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
    save(out, "shield_accuracy", rows, summarize_accuracy, plot_accuracy)
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
                med, p90 = quantiles([r[f"err_{name}"] for r in rs], (0.5, 0.9))
                s[f"{tag}{name}_med"] = med
                s[f"{tag}{name}_p90"] = p90
        out.append(s)
    return out


def plot_accuracy(rows: list[dict[str, Any]], path: Path) -> None:
    """CDFs of the relative errors (log x): rows of panels = state sources, columns = contact
    forces, object position, object rotation; one colour per perturbation group, solid over
    all perturbations, dashed over the filtered ones (same contacts, MuJoCo linear)."""
    plt = pyplot()
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
    print_table(summary, cols, 2)
    print("\nfiltered (same contacts and MuJoCo linear):")
    cols = ["source", "perturbation", "n_filtered"]
    cols += [f"filt_{n}_{q}" for n in ("force", "pos", "rot") for q in ("med", "p90")]
    print_table(summary, cols, 2)


def add_parser(sub: Any, common: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """The ``accuracy`` subcommand (its options after ``common``'s)."""
    fmt = argparse.ArgumentDefaultsHelpFormatter
    a = sub.add_parser(
        "accuracy", parents=[common], help="linearisation vs MuJoCo", formatter_class=fmt,
        description=(__doc__ or "").split("\n\n")[0],
    )  # fmt: skip
    a.add_argument("--states", type=positive, default=20, help="states per source")
    a.add_argument("--sources", type=csv_list(str, SOURCES), default=list(SOURCES),
                   help="comma-separated state sources: settled,random,policy")  # fmt: skip
    a.add_argument("--deltas", type=csv_list(float), default=[0.01, 0.05],
                   help="single-servo setpoint changes [rad], comma-separated")  # fmt: skip
    a.add_argument("--every", type=positive, default=3, help="rollout steps between states")
    a.add_argument("--actions", type=positive, default=4,
                   help="whole-action perturbations per state (policy states: 1)")  # fmt: skip
    a.set_defaults(run=run, parser=a)
    return a


def run(args: argparse.Namespace) -> list[dict[str, Any]]:
    """Run the measurement from parsed options; print its tables; return its summary rows."""
    if any(not (np.isfinite(x) and x > 0) for x in args.deltas):
        args.parser.error("--deltas must be finite numbers > 0 [rad]")
    out = Path(args.out)
    t0 = time.perf_counter()
    rows = run_accuracy(
        out, seed=args.seed, states=args.states, deltas=args.deltas, sources=args.sources,
        every=args.every, actions=args.actions, progress=not args.no_progress,
    )  # fmt: skip
    summary = summarize_accuracy(rows)
    _print_accuracy(summary)
    names = ("shield_accuracy.csv", "shield_accuracy_summary.csv", "shield_accuracy.png")
    wrote(out, names, t0)
    return summary
