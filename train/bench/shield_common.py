"""What the QP shield benchmarks share (``python -m train.bench shield accuracy|latency|effect``).

Each subcommand prints a table and writes ``shield_<name>.csv`` (one row per measurement),
``shield_<name>_summary.csv`` and ``shield_<name>.png`` under ``--out`` (default
``docs/bench``; :func:`save`). Runs are deterministic for a given ``--seed``, except for the
wall times of ``latency`` (the states and actions they are taken at are deterministic). The
env is ``FourFingerRotate`` (sphere, gravity, torsional friction: the shipped policy's
settings); "the policy" is the shipped ``policies/four_finger_sphere``, acting
deterministically on observations normalised with its frozen ``VecNormalize`` statistics
(:func:`shipped_policy`, :func:`train.policy.load_policy`); "random" draws actions uniformly
from ``[-1, 1]^12``. The measurements: :mod:`train.bench.shield_accuracy` (the
linearisation against MuJoCo), :mod:`train.bench.shield_latency` (the shield's wall time per
step, DAQP against OSQP), :mod:`train.bench.shield_effect` (episodes with and without the
shield).

*Slip event*: a policy step at whose end some contact of a finger link (the observed links
``envs.four_finger.CONTACT_LINKS``; palm and floor excluded) with the object has its force on
the surface of MuJoCo's friction cone: with ``f`` the contact's ``efc_force`` rows (``f_0``
the normal force, ``f_1, f_2`` tangential, ``f_3`` the torsional moment of a ``condim`` 4
contact) and ``mu_j = contact.friction[j - 1]``, ``sqrt(sum_j (f_j / mu_j)^2) / f_0 >= 0.99``
(counted once per step however many contacts slip). MuJoCo's ``efc_state ==
mjCNSTRSTATE_CONE`` is not used: the constant exists in MuJoCo 4.0, but with the env's PGS
(dual) solver ``efc_state`` is set by ``dualState`` (``src/engine/engine_solver.c``), which
labels a force exactly on the cone surface (PGS projects a sliding contact's friction onto
the ellipsoid: the ratio is 1 to 1e-9) ``CONE`` or ``SATISFIED`` depending on round-off, so
a sliding contact may carry either label. The per-episode CSV reports both counts
(``slip_contacts``, ``slip_contacts_cone_state``). "End of a step" is the contact data the
env leaves after the step (the last substep's collision detection, as in the observation).
*Contact loss*: a finger link that touched the object at the start of a step and does not at
its end (counted per link).
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
from numpy.typing import NDArray

from envs.four_finger import CONTACT_LINKS, FourFingerRotate
from ihm.contacts import body_subtree, object_contact_ids
from stability.cli import ArgumentParser
from stability.io import write_csv
from train.policy import SHIPPED, load_policy

__all__ = [
    "AGENTS",
    "SLIP_RATIO",
    "Links",
    "Policy",
    "common_options",
    "cone_ratios",
    "csv_list",
    "fmt",
    "links_outside",
    "make_env",
    "positive",
    "print_table",
    "pyplot",
    "quantiles",
    "save",
    "shipped_policy",
    "wrote",
]

AGENTS = ("random", "policy")
SLIP_RATIO = 0.99  # cone ratio at and above which a contact slips (on the cone surface)
Policy = Callable[[NDArray[np.float32]], NDArray[np.float32]]


def shipped_policy(threads: int = 1) -> tuple[Policy, dict[str, Any]]:
    """The shipped policy (deterministic, with its observation normalisation) and its env
    options; torch on ``threads`` threads."""
    import torch

    torch.set_num_threads(threads)
    return load_policy(SHIPPED)


def make_env(opts: dict[str, Any] | None = None) -> FourFingerRotate:
    """``FourFingerRotate(**opts)`` (the default env without options)."""
    return FourFingerRotate(**(opts or {}))


class Links:
    """The finger-link/object contacts of a model's data (links: ``CONTACT_LINKS``)."""

    def __init__(self, model: mujoco.MjModel) -> None:
        self.link_of_body = {model.body(n).id: k for k, n in enumerate(CONTACT_LINKS)}
        in_obj = body_subtree(model, model.body("object").id)
        self.geom_obj = in_obj[model.geom_bodyid].tolist()
        self.geom_link = [self.link_of_body.get(int(b), -1) for b in model.geom_bodyid]

    def contacts(self, data: mujoco.MjData) -> list[tuple[int, int]]:
        """``(link index, contact index)`` of every active finger-link/object contact."""
        found = object_contact_ids(data, self.geom_obj)
        return [(self.geom_link[g], i) for i, g, _ in found if self.geom_link[g] >= 0]

    def touching(self, data: mujoco.MjData) -> set[int]:
        """Indices (into CONTACT_LINKS) of the finger links touching the object."""
        return {k for k, _ in self.contacts(data)}


def cone_ratios(data: mujoco.MjData, contact_ids: Sequence[int]) -> NDArray[np.float64]:
    """``sqrt(sum_j (f_j / mu_j)^2) / f_0`` of each contact (slip event, module docstring):
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


def quantiles(x: Sequence[float] | NDArray, qs: Sequence[float]) -> list[float]:
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    if len(x) == 0:
        return [math.nan] * len(qs)
    return [float(v) for v in np.percentile(x, [100 * q for q in qs])]


def fmt(v: Any, nd: int = 3) -> str:
    if isinstance(v, float):
        return "nan" if not np.isfinite(v) else f"{v:.{nd}g}" if abs(v) < 1e-3 else f"{v:.{nd}f}"
    return str(v)


def print_table(rows: list[dict[str, Any]], cols: Sequence[str], nd: int = 3) -> None:
    cells = [[fmt(r.get(c, ""), nd) for c in cols] for r in rows]
    widths = [max(len(c), *(len(row[j]) for row in cells)) for j, c in enumerate(cols)]
    print("  ".join(c.rjust(w) for c, w in zip(cols, widths, strict=True)))
    for row in cells:
        print("  ".join(v.rjust(w) for v, w in zip(row, widths, strict=True)))


def pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save(
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
    write_csv(out / f"{name}.csv", rows, float_format=".6g")
    summary = summarize(rows)
    write_csv(out / f"{name}_summary.csv", summary, float_format=".6g")
    plot(summary if plot_summary else rows, out / f"{name}.png")


def wrote(out: Path, names: Sequence[str], t0: float) -> None:
    """The closing line of a subcommand: the files it wrote and its wall time since ``t0``."""
    print(f"wrote {', '.join(str(out / n) for n in names)} ({time.perf_counter() - t0:.0f} s)")


# -- command line ----------------------------------------------------------------------------
def csv_list(kind: type, choices: Sequence[Any] | None = None) -> Callable[[str], list[Any]]:
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


def positive(text: str) -> int:
    v = int(text)
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {v}")
    return v


def common_options() -> argparse.ArgumentParser:
    """The options of every subcommand (a parent parser): ``--out``, ``--seed``,
    ``--no-progress``."""
    common = ArgumentParser(add_help=False)
    common.add_argument("--out", default="docs/bench", help="directory for the CSV and PNG")
    common.add_argument("--seed", type=int, default=0, help="seed of states, actions, grasps")
    common.add_argument("--no-progress", action="store_true", help="no progress bar")
    return common
