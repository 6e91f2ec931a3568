"""Cross-check of ``method="planar"`` against a naive exhaustive 6^m-state checker.

``naive_planar.naive_stable`` is written from the thesis equations (ch. 4) with
no code shared with ``stability``. It is first validated on its own: against
the thesis' results table (tab. three_contact) and between its two LP backends.
Then ``stability.solve(..., method="planar")`` must agree with it on every one
of several hundred random (grasp, wrench, preload) cases, many of them placed
just inside and just outside the stability boundary found by ``MaxDisturbance``.
"""

from __future__ import annotations

import numpy as np
import pytest
from naive_planar import naive_residuals, naive_stable

# -- the thesis grasp (fig. grasp2, tab. three_contact) ------------------------------
THESIS_POINTS = [(-1.0, 0.0), (0.0, -1.0), (1.0, 0.0)]
THESIS_NORMALS = [(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0)]
THESIS_MU = 0.5
# (wrench, preload P at every contact, stable, forces c_i = (c_n, c_t) or None)
THESIS_TABLE = [
    ((0, 0, 0), 0.0, True, [(0, 0), (0, 0), (0, 0)]),
    ((0, 0, 0), 1.0, True, [(1, -0.5), (1, 0), (1, 0.5)]),
    ((0, -1, 0), 0.0, True, [(0, 0), (1, 0), (0, 0)]),
    ((0, -2, 0), 0.0, True, [(0, 0), (2, 0), (0, 0)]),
    ((0, 1, 0), 0.0, False, None),
    ((0, 1, 0), 1.0, True, [(1, -0.5), (0, 0), (1, 0.5)]),
    ((0, 1.1, 0), 1.0, False, None),
]

RESIDUAL_TOL = 1e-7  # on every model condition of a returned solution
REL_STEP = 1e-3  # near-boundary cases sit at s* (1 -/+ REL_STEP)
ABS_STEP = 1e-6  # ... plus this, outside, so that s* = 0 still gets an outside point
CAP = 50.0
N_GRASPS = {2: 90, 3: 80, 4: 35}
SEED = 20240917


# -- 1. the naive checker itself ------------------------------------------------------
@pytest.mark.parametrize("backend", ["highspy", "scipy"])
@pytest.mark.parametrize("wrench, preload, stable, forces", THESIS_TABLE)
def test_naive_reproduces_thesis_table(backend, wrench, preload, stable, forces):
    ok, c, r, states = naive_stable(
        THESIS_POINTS,
        THESIS_NORMALS,
        THESIS_MU,
        wrench,
        preload,
        backend=backend,
        return_details=True,
    )
    assert ok is stable
    if not stable:
        assert c is None
        return
    res = naive_residuals(THESIS_POINTS, THESIS_NORMALS, THESIS_MU, wrench, preload, c, r)
    assert max(res.values()) <= RESIDUAL_TOL, res
    # the table's forces are unique here: the naive solution must reproduce them
    np.testing.assert_allclose(c, np.array(forces, dtype=float), atol=1e-7)


def _random_grasp(rng: np.random.Generator, m: int):
    """Points in [-1, 1]^2; normals mostly towards the centroid, some fully random."""
    points = rng.uniform(-1.0, 1.0, size=(m, 2))
    if rng.random() < 0.7:
        inward = points.mean(axis=0) - points
        inward /= np.maximum(np.linalg.norm(inward, axis=1, keepdims=True), 1e-9)
        normals = inward + 0.5 * rng.normal(size=(m, 2))
    else:
        normals = rng.normal(size=(m, 2))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    mu = float(rng.uniform(0.1, 1.0)) if rng.random() < 0.75 else rng.uniform(0.1, 1.0, size=m)
    if rng.random() < 0.5:
        preload = 0.0
    elif rng.random() < 0.3:
        preload = float(rng.uniform(0.0, 2.0))
    else:
        preload = rng.uniform(0.0, 2.0, size=m)
    return points, normals, mu, preload


def _random_direction(rng: np.random.Generator) -> np.ndarray:
    d = rng.normal(size=3)
    if rng.random() < 0.4:
        d[2] = 0.0  # pure force
    return d / np.linalg.norm(d)


def _make_cases(m: int):
    """Deterministic grasps for ``m`` contacts: (points, normals, mu, preload, w, d)."""
    rng = np.random.default_rng([SEED, m])
    cases = []
    for _ in range(N_GRASPS[m]):
        points, normals, mu, preload = _random_grasp(rng, m)
        w = _random_direction(rng) * rng.uniform(0.0, 3.0)
        d = _random_direction(rng)
        cases.append((points, normals, mu, preload, w, d))
    return cases


def test_naive_backends_agree():
    """The warm-started highspy loop and fresh scipy LPs give the same answers."""
    rng = np.random.default_rng([SEED, 99])
    answers = []
    for m in (2, 2, 2, 2, 2, 2, 2, 2, 2, 2, 3, 3, 3, 3, 3, 3, 3, 3):
        points, normals, mu, preload = _random_grasp(rng, m)
        w = _random_direction(rng) * rng.uniform(0.0, 2.0)
        a = naive_stable(points, normals, mu, w, preload, backend="highspy")[0]
        b = naive_stable(points, normals, mu, w, preload, backend="scipy")[0]
        assert a == b, (points, normals, mu, preload, w)
        answers.append(a)
    assert any(answers) and not all(answers)  # both outcomes exercised


# -- 2. planar vs naive ----------------------------------------------------------------
@pytest.fixture(scope="module")
def stability():
    import stability

    assert "planar" in stability.available_methods()
    return stability


def _fmt(x) -> str:
    return np.array2string(np.asarray(x, dtype=float), precision=17, separator=", ")


# m = 4: the naive checker's 6^4 states per case make it the long one (the slow tier)
@pytest.mark.parametrize(
    "m", [pytest.param(m, marks=pytest.mark.slow) if m == 4 else m for m in sorted(N_GRASPS)]
)
def test_planar_agrees_with_naive(stability, m):
    failures: list[str] = []
    counts = {"cases": 0, "stable": 0, "unstable": 0, "boundary_pairs": 0, "capped": 0}

    for k, (points, normals, mu, preload, w_rand, d) in enumerate(_make_cases(m)):
        grasp = stability.Grasp(points, normals, mu)
        data = (
            f"[m={m} #{k}] points={_fmt(points)} normals={_fmt(normals)} "
            f"mu={_fmt(mu)} preload={_fmt(preload)}"
        )

        # near-boundary magnitudes along d from the planar solver's own MaxDisturbance
        wrenches = [("random", w_rand)]
        md = stability.solve(
            grasp,
            stability.MaxDisturbance(direction=d, preload=preload, cap=CAP),
            method="planar",
        )
        s_star = md.value
        if md.stable and s_star is not None:
            if max(md.residuals().values()) > RESIDUAL_TOL * max(1.0, s_star):
                failures.append(
                    f"{data} MaxDisturbance d={_fmt(d)}: s*={s_star!r} residuals {md.residuals()}"
                )
            wrenches.append(("s*(1-1e-3)", s_star * (1 - REL_STEP) * d))
            if md.stats.get("capped"):
                counts["capped"] += 1
            else:
                counts["boundary_pairs"] += 1
                wrenches.append(("s*(1+1e-3)", (s_star * (1 + REL_STEP) + ABS_STEP) * d))
        else:
            # not even s = 0 is stable: then no magnitude along d is, check a few
            if naive_stable(points, normals, mu, np.zeros(3), preload)[0]:
                failures.append(
                    f"{data} MaxDisturbance d={_fmt(d)} says unstable at s=0 "
                    f"(value={s_star!r}) but naive is stable at w=0"
                )
            wrenches.append(("unstable-dir", 1.0 * d))

        for label, w in wrenches:
            sol = stability.solve(
                grasp, stability.Existence(wrench=w, preload=preload), method="planar"
            )
            ok, c, r, states = naive_stable(points, normals, mu, w, preload, return_details=True)
            counts["cases"] += 1
            counts["stable" if ok else "unstable"] += 1
            case = f"{data} wrench={_fmt(w)} ({label}, d={_fmt(d)}, s*={s_star!r})"
            if ok:
                nres = naive_residuals(points, normals, mu, w, preload, c, r)
                if max(nres.values()) > RESIDUAL_TOL:
                    failures.append(f"{case}: NAIVE solution residuals {nres} states {states}")
            if bool(sol.stable) != ok:
                failures.append(
                    f"{case}: planar stable={sol.stable} naive stable={ok} "
                    f"(naive states {states}, forces {None if c is None else _fmt(c)}, "
                    f"motion {None if r is None else _fmt(r)}; planar states {sol.states})"
                )
            if sol.stable:
                res = sol.residuals()
                if max(res.values()) > RESIDUAL_TOL:
                    failures.append(f"{case}: planar residuals {res}")
            if label == "s*(1+1e-3)" and sol.stable:
                failures.append(f"{case}: planar Existence is stable just beyond MaxDisturbance s*")

    print(f"m={m}: {counts}")
    assert counts["stable"] > 0 and counts["unstable"] > 0
    assert not failures, f"{len(failures)} failure(s) for m={m}:\n" + "\n".join(failures)
