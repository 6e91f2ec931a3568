"""Grasp contacts as :class:`ContactGroup` records, merged and reduced.

:func:`merge_contacts` merges MuJoCo contacts that touch at one point; :func:`reduce_patches`
reduces a face contact reported as many points to two (``keep == 0``: the line through
its centre of pressure) or to at most ``keep`` points that carry its wrench. What each
does, and the conventions (world frame, ``n`` into the object, forces of the hand on the
object): the module docstring of :mod:`ihm.contacts`, which calls them.

Normal stiffness (``ContactGroup.stiffness`` [N/m], ``compliance="mujoco"``): the MuJoCo
contacts a group stands for are springs in parallel, each projected on the group's normal
``n`` (a spring ``k_i`` along ``n_i`` gives ``k_i (n_i . n)^2`` along ``n``), so merging
sums them. ``reduce="extremes"`` adds a dropped contact's stiffness to the kept point its
force goes to (the patch's total stiffness is kept). ``reduce="line"`` splits the
patch's total ``K = sum k_i`` between the two ends ``s_lo < s_hi`` on the line by the
lever rule, ``k_hi = K (s_bar - s_lo) / (s_hi - s_lo)`` with ``s_bar = sum k_i s_i / K``
the patch's centre of stiffness along the line (``s_i``: each point's coordinate on it),
so that the total and the first moment along the line are kept; each end keeps at least
1 % of ``K`` (the spring law needs ``k > 0``) where the centre of stiffness lies outside
the ends.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

__all__ = ["THIN_PATCH_M", "ContactGroup", "ContactLaw", "merge_contacts", "reduce_patches"]


class ContactLaw(NamedTuple):
    """MuJoCo's static law of one contact (:mod:`ihm.contact_law`): its ``solimp`` (5
    numbers) and how far it presses into its margin [m] at the state (0 for a contact not
    touching yet)."""

    solimp: tuple[float, ...]
    depth: float

    @classmethod
    def of(cls, con: Any, depth: float) -> ContactLaw:
        """The law of MuJoCo contact ``con`` (an ``MjContact``) at ``depth`` [m]."""
        return cls(tuple(float(v) for v in con.solimp[:5]), float(depth))


@dataclass
class ContactGroup:
    """One grasp contact: MuJoCo contacts between the same hand and object bodies, merged
    (world frame). ``pair``: (hand geom, object geom) of the first; ``bodies``: (hand body,
    object body); ``pos``: the merged contacts' positions [m]; ``frame``: rows n, t1, t2,
    ``n`` into the object; ``force_world``: the summed force of the hand on the object
    [N]; ``mu``: the smallest friction coefficient; ``ids``: the MuJoCo contact indices;
    ``stiffness``: the normal stiffness of the springs it stands for [N/m] (module
    docstring; 0 where not computed); ``law``: MuJoCo's static law of the first contact
    (:class:`ContactLaw`; None where not read)."""

    pair: tuple[int, int]
    bodies: tuple[int, int]
    pos: list[NDArray[np.float64]]
    frame: NDArray[np.float64]
    force_world: NDArray[np.float64]
    mu: float
    ids: list[int]
    stiffness: float = 0.0
    law: ContactLaw | None = None


def merge_contacts(contacts: list[ContactGroup], merge_tol: float) -> list[ContactGroup]:
    """Contacts between the same bodies within ``merge_tol`` [m] of a group's mean position
    and with normals within 1e-3 rad merged into that group (forces summed, the smallest
    friction), in MuJoCo's order."""
    groups: list[ContactGroup] = []
    for c in contacts:
        pos = c.pos[0]
        for g in groups:
            if (
                g.bodies == c.bodies
                and np.linalg.norm(np.mean(g.pos, axis=0) - pos) <= merge_tol
                and g.frame[0] @ c.frame[0] >= np.cos(1e-3)
            ):
                g.pos.append(pos)
                g.force_world += c.force_world
                g.ids.append(c.ids[0])
                g.mu = min(g.mu, c.mu)
                g.stiffness += c.stiffness * float(g.frame[0] @ c.frame[0]) ** 2
                break
        else:
            groups.append(c)
    return groups


def _third_point(p: list[ContactGroup], pts: NDArray[np.float64], two: list[int]) -> int:
    """The point whose triangle with ``two`` holds the patch's centre of pressure deepest
    (largest smallest barycentric coordinate, in the patch plane): the kept normal forces
    can then stay >= 0."""
    frame = p[0].frame
    fn = np.array([g.force_world for g in p]) @ frame[0]
    cop = (fn @ pts) / fn.sum() if fn.sum() > 0 else pts.mean(axis=0)
    Y, c = pts @ frame[1:].T, cop @ frame[1:].T
    best, best_k = -np.inf, -1
    for k in range(len(pts)):
        if k in two:
            continue
        tri = np.vstack([Y[[two[0], two[1], k]].T, np.ones(3)])
        if abs(np.linalg.det(tri)) < 1e-18:
            continue  # collinear
        lam = np.linalg.solve(tri, np.r_[c, 1.0])
        if lam.min() > best:
            best, best_k = float(lam.min()), k
    if best_k < 0:  # all collinear: the farthest from the first two
        far = np.linalg.norm(pts[:, None] - pts[two][None], axis=2).min(axis=1)
        far[two] = -1.0
        best_k = int(np.argmax(far))
    return best_k


THIN_PATCH_M = 1e-5  # a patch narrower than this [m rms] is a strip for reduce="line"


def _skew(v: NDArray[np.float64]) -> NDArray[np.float64]:
    """``[v]_x``: ``_skew(v) @ f == cross(v, f)``."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _patch_wrench(
    pts: NDArray[np.float64], forces: NDArray[np.float64], centre: NDArray[np.float64]
) -> NDArray[np.float64]:
    """The wrench ``(f, torque about centre)`` of forces (k, 3) at points (k, 3)."""
    return np.r_[forces.sum(axis=0), np.cross(pts - centre, forces).sum(axis=0)]


def _wrench_map(pts: NDArray[np.float64], centre: NDArray[np.float64]) -> NDArray[np.float64]:
    """(6, 3k): stacked forces at ``pts`` to their wrench about ``centre``."""
    return np.vstack(
        [np.hstack([np.eye(3)] * len(pts)), np.hstack([_skew(q - centre) for q in pts])]
    )


def _line_patch(p: list[ContactGroup], wide: bool = False) -> list[ContactGroup] | None:
    """A patch as two contacts on the line through its centre of pressure along its longest
    extent, at the patch's boundary (its points' convex hull), forces carrying the patch's
    whole wrench (exact for coplanar points: about the centre of pressure the normal forces
    have no in-plane moment). None for a patch whose points are collinear or unloaded.
    ``wide``: each end split across the line where the hull ends on either side (four
    points; ``reduce="rect"``), its force and stiffness by the lever rule."""
    from scipy.spatial import ConvexHull, QhullError

    frame = p[0].frame
    pts = np.array([np.mean(g.pos, axis=0) for g in p])
    forces = np.array([g.force_world for g in p])
    fn = forces @ frame[0]
    if fn.sum() <= 0:
        return None
    centre = pts.mean(axis=0)
    Y = (pts - centre) @ frame[1:].T  # in-plane coordinates (t1, t2)
    cop = (fn @ pts) / fn.sum()
    c2 = (cop - centre) @ frame[1:].T
    _, sv, vt = np.linalg.svd(Y - Y.mean(axis=0), full_matrices=False)
    u2 = vt[0]
    along = (Y - c2) @ u2
    if sv[1] <= THIN_PATCH_M * np.sqrt(len(Y)):  # a strip: its extent along the line
        s_lo, s_hi = float(along.min()), float(along.max())
    else:
        try:
            hull = ConvexHull(Y)
        except (QhullError, ValueError):
            return None
        a, b = hull.equations[:, :2], hull.equations[:, 2]
        au, slack = a @ u2, -(a @ c2 + b)  # a.(c + s u) + b <= 0  <=>  s (a.u) <= slack
        s_hi = float(np.min(slack[au > 1e-12] / au[au > 1e-12]))
        s_lo = float(np.max(slack[au < -1e-12] / au[au < -1e-12]))
    u3 = u2 @ frame[1:]
    ends = np.array([cop + s_lo * u3, cop + s_hi * u3])
    W = _patch_wrench(pts, forces, centre)
    A = _wrench_map(ends, centre)
    f0 = np.tile(forces.sum(axis=0) / 2, 2)
    f = f0 + np.linalg.pinv(A) @ (W - A @ f0)
    ids = [i for g in p for i in g.ids]
    mu = min(g.mu for g in p)
    k_ends = _lever_split(np.array([g.stiffness for g in p]), along, s_lo, s_hi)
    line = [replace(p[0], pos=[ends[k]], ids=list(ids) if k == 0 else [], mu=mu,
                    force_world=f[3 * k : 3 * k + 3], stiffness=k_ends[k])
            for k in range(2)]  # fmt: skip
    if not wide or sv[1] <= THIN_PATCH_M * np.sqrt(len(Y)):
        return line
    # each end split across the line, to where the patch's hull ends on either side, by
    # the lever rule (the end's force and stiffness, and so the patch's wrench, kept)
    v2 = vt[1]
    v3 = v2 @ frame[1:]
    out = []
    for k, e in enumerate(line):
        ce = c2 + (s_lo if k == 0 else s_hi) * u2
        av, slack = a @ v2, -(a @ ce + b)
        side = slack > 1e-9  # not the face the end lies on
        up, dn = side & (av > 1e-12), side & (av < -1e-12)
        w_hi = float(np.min(slack[up] / av[up])) if up.any() else 0.0
        w_lo = float(np.max(slack[dn] / av[dn])) if dn.any() else 0.0
        if min(w_hi, -w_lo) <= THIN_PATCH_M:  # an end at a corner: kept as it is
            out.append(e)
            continue
        share = (-w_lo) / (w_hi - w_lo)  # of the end's load at w_hi
        for w, frac, first in ((w_lo, 1 - share, True), (w_hi, share, False)):
            out.append(replace(e, pos=[e.pos[0] + w * v3], ids=list(e.ids) if first else [],
                               force_world=frac * e.force_world,
                               stiffness=frac * e.stiffness))  # fmt: skip
    return out


def _lever_split(k: NDArray[np.float64], s: NDArray[np.float64], s_lo: float,
                 s_hi: float) -> tuple[float, float]:  # fmt: skip
    """The total ``K = sum k`` split between ends at ``s_lo < s_hi`` so that the first moment
    ``sum k s`` is kept, each end keeping at least 1 % of ``K`` (module docstring)."""
    total = float(k.sum())
    if total <= 0 or s_hi <= s_lo:
        return total / 2, total / 2
    w = float(np.clip((float(k @ s) / total - s_lo) / (s_hi - s_lo), 0.01, 0.99))
    return total * (1 - w), total * w


def reduce_patches(groups: list[ContactGroup], keep: int) -> list[ContactGroup]:
    """Each patch (same hand and object body, normals within 1e-3 rad) to at most ``keep``
    contacts, farthest first; a dropped contact's force goes to the nearest kept one and
    the kept forces are corrected to carry the patch's wrench. ``keep == 0``: the line
    through the centre of pressure (:func:`_line_patch`)."""
    patches: list[list[ContactGroup]] = []
    for g in groups:
        for p in patches:
            if p[0].bodies == g.bodies and p[0].frame[0] @ g.frame[0] >= np.cos(1e-3):
                p.append(g)
                break
        else:
            patches.append([g])
    out = []
    for p in patches:
        if keep <= 0 and len(p) > 2:
            line = _line_patch(p, wide=keep < 0)
            if line is not None:
                out.extend(line)
                continue
        n_keep = 2 if keep <= 0 else keep
        if len(p) <= n_keep:
            out.extend(p)
            continue
        pts = np.array([np.mean(g.pos, axis=0) for g in p])
        dist = np.linalg.norm(pts[:, None] - pts[None], axis=2)
        i, j = np.unravel_index(np.argmax(dist), dist.shape)
        chosen = [int(i), int(j)]
        if n_keep >= 3:  # the third: the triangle that best contains the centre of pressure
            chosen.append(_third_point(p, pts, chosen))
        while len(chosen) < n_keep:
            far = dist[:, chosen].min(axis=1)
            far[chosen] = -1.0
            chosen.append(int(np.argmax(far)))
        kept = [replace(p[k], pos=list(p[k].pos), ids=list(p[k].ids),
                        force_world=p[k].force_world.copy()) for k in chosen]  # fmt: skip
        for k, g in enumerate(p):
            if k in chosen:
                continue
            near = kept[int(np.argmin(dist[k, chosen]))]
            near.force_world = near.force_world + g.force_world
            near.ids = near.ids + g.ids
            near.mu = min(near.mu, g.mu)
            near.stiffness += g.stiffness * float(near.frame[0] @ g.frame[0]) ** 2
        # keep the patch's wrench: f = f0 + A^+ (W - A f0), A the kept points' wrench map
        centre = pts.mean(axis=0)
        W = _patch_wrench(pts, np.array([g.force_world for g in p]), centre)
        A = _wrench_map(pts[chosen], centre)
        f0 = np.concatenate([g.force_world for g in kept])
        f = f0 + np.linalg.pinv(A) @ (W - A @ f0)
        for k, g in enumerate(kept):
            g.force_world = f[3 * k : 3 * k + 3]
        out.extend(kept)
    return out
