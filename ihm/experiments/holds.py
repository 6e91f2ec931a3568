"""Static holds against the grasp model: ``python -m ihm.experiments.holds --out DIR``.

The Barrett experiments (:mod:`ihm.experiments.barrett`) compare predictions with a ramp's
distance rule, which on MuJoCo's soft friction counts slow sliding and depends on the ramp
rate (:mod:`ihm.holds`). This runner measures the same loads on the same settled grasps by
the static hold (:func:`ihm.holds.static_resistance`: the largest constant load held for
2.3 s after a 0.2 s ramp, within 2 mm / 0.05 rad, no new contact) and compares it with
``stability.solve(..., method="modesearch")`` on the grasp read off that state, with the
thesis' unit springs (``grasp_from_mujoco(model, data)``) and with MuJoCo's stiffness
(``compliance="mujoco"``, contacts preloaded with the settled forces:
:func:`ihm.sim_maps.scene_disturbance`).

Cases, as the experiments load them (nonbackdrivable protocol of
:func:`ihm.scenes.load_scene`, directions in the object frame):

* ``barrett_box``: seat [0, 0.01, 0.01, 0] N m, preload [0, 0, 0, 0] and [0, 0.1, 0.1, 0]
  N m, forces through the centre of mass in the object xy- and xz-planes, ``n`` directions
  each (``a = 2 pi k / n`` from the plane's first axis), cap 10 N; the grasp for the
  predictions is read with the ratchet released, as :func:`ihm.sim_maps.analysis_map` does.
* ``barrett_cube``: seat [0, 0.02, 0.02, 0.005] N m, fingers 1 and 2 at 0.1 N m, the thumb
  at tau3 = 0, 0.045, 0.09 N m; a force along object +z through the object origin (cap 5 N)
  and a torque about object +x and -x (cap 0.2 N m), as ``barrett.cube`` applies them.

Each direction is held in three variants (:data:`VARIANTS`): the main one (the defaults of
:class:`ihm.holds.HoldOptions`), with the rest check of the measurement in the notebook
(``hold_at_rest``: the object also moves less than 0.01 mm and 2e-4 rad over the last
0.5 s) and with a 6 s hold (``hold_long``). Below the main value, the loads
:data:`BELOW` (fractions of it) are tried once each; the first not held is
``hold_fails_below`` (the bisection assumes there is none).

Writes ``DIR/holds.csv`` (one row per case and direction: the holds [N or N m], their
bracket, the predictions and their solver status, the experiments' ramp value of the same
direction where their ``*_summary.json`` has it) and prints, per map and model, the
agreement with the holds in the measures of :func:`ihm.sim_maps.agreement` (direction
agreement: both capped or both finite; median ``|ln(pred / hold)|`` over directions finite
and positive in both), for reference the experiments' own agreement with the ramp, and the
median ratio of the ramp to the hold.
"""

from __future__ import annotations

import csv
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from stability import solve
from stability.cli import ArgumentParser
from stability.io import write_csv
from stability.maps import ResistibleMap, plane_axes

from .. import scenes
from ..contacts import grasp_from_mujoco
from ..holds import HoldOptions, hold_trial, static_resistance
from ..sim_maps import agreement, map_value, scene_disturbance
from . import MUJOCO_READ
from .barrett import TIME_LIMIT, seated

__all__ = ["COLUMNS", "box_rows", "cube_rows", "main", "read_rows", "summarise"]

BOX_SEAT = [0.0, 0.01, 0.01, 0.0]
BOX_PRELOADS = {"no preload": [0.0, 0.0, 0.0, 0.0], "preload 0.1 N m": [0.0, 0.1, 0.1, 0.0]}
BOX_CAP = 10.0  # [N]
CUBE_SEAT = [0.0, 0.02, 0.02, 0.005]
CUBE_TAUS = (0.0, 0.045, 0.09)  # thumb commands [N m]
CUBE_LOADS = {"force +z [N]": (np.array([0, 0, 1.0, 0, 0, 0]), 5.0),
              "torque about +x [N m]": (np.array([0, 0, 0, 1.0, 0, 0]), 0.2),
              "torque about -x [N m]": (np.array([0, 0, 0, -1.0, 0, 0]), 0.2)}  # fmt: skip
#: variants of the hold (``HoldOptions`` fields beyond the cap): the main one (the
#: defaults), with the rest check measured in docs/notebook (0.01 mm, 2e-4 rad in the last
#: 0.5 s) and with a longer hold [s]
VARIANTS = {"hold": {}, "hold_at_rest": {"rest_s": 0.5}, "hold_long": {"hold_s": 6.0}}
#: loads below the main hold value, as fractions of it, tried once each (monotonicity)
BELOW = (0.5, 0.8, 0.9, 0.95)
COLUMNS = ["scene", "map", "angle_deg", "tau3_Nm", "hold", "hold_capped", "hold_lo", "hold_hi",
           "hold_reason", "hold_trials", "hold_fails_below", "hold_at_rest",
           "hold_at_rest_capped", "hold_long", "hold_long_capped", "unit", "unit_capped",
           "unit_status", "mujoco", "mujoco_capped", "mujoco_status", "ramp",
           "ramp_capped"]  # fmt: skip
#: CSV column -> grasp_from_mujoco options
MODELS: dict[str, dict[str, Any]] = {"unit": {"compliance": "unit"}, "mujoco": MUJOCO_READ}


def _predict(
    grasp: Any, d: np.ndarray, commands: np.ndarray, cap: float
) -> tuple[float, bool, str]:
    """modesearch's MaxDisturbance for the object-frame wrench ``d`` (about the object
    origin) on the settled ``grasp``: (value, capped, status)."""
    sol = solve(grasp, scene_disturbance(grasp, d, commands, cap), method="modesearch",
                time_limit=TIME_LIMIT)  # fmt: skip
    value, capped = map_value(sol)
    return value, capped, str(sol.status)


def _hold(loaded: Any, w: np.ndarray, cap: float) -> dict[str, Any]:
    """The static hold of the world wrench direction ``w`` in each of :data:`VARIANTS`, and
    the smallest of the loads :data:`BELOW` the main value that is not held (empty: all
    held), as CSV cells."""
    m, d = loaded
    holds = {col: static_resistance(m, d, w, ratchet=loaded.ratchet,
                                    options=HoldOptions(cap=cap, **kw))
             for col, kw in VARIANTS.items()}  # fmt: skip
    main = holds["hold"]
    out: dict[str, Any] = {"hold_lo": main.bracket[0], "hold_hi": main.bracket[1],
                           "hold_reason": main.reason, "hold_trials": len(main.trials)}  # fmt: skip
    for col, h in holds.items():
        out.update({col: h.value, f"{col}_capped": int(h.capped)})
    if not main.capped and main.value > 0:
        for frac in BELOW:
            t = hold_trial(m, d, w, frac * main.value, ratchet=loaded.ratchet)
            if not t.held:
                out["hold_fails_below"] = t.load
                break
    return out


def _predictions(grasps: dict[str, Any], d: np.ndarray, commands: np.ndarray,
                 cap: float) -> dict[str, Any]:  # fmt: skip
    out: dict[str, Any] = {}
    for col, g in grasps.items():
        v, c, status = _predict(g, d, g.full_commands(commands), cap)
        out.update({col: v, f"{col}_capped": int(c), f"{col}_status": status})
    return out


def box_rows(n: int = 12, log: Any = None) -> list[dict[str, Any]]:
    """The ``barrett_box`` rows: per plane and preload, ``n`` object-frame force directions."""
    rows = []
    angles = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    for plane in ("xy", "xz"):
        i, j = plane_axes(plane)
        units = np.zeros((n, 3))
        units[:, i], units[:, j] = np.cos(angles), np.sin(angles)
        for tag, pre in BOX_PRELOADS.items():
            t = time.perf_counter()
            loaded = scenes.load_scene("barrett_box", preload=pre, nonbackdrivable=True,
                                       seat=BOX_SEAT)  # fmt: skip
            m, d = loaded
            b = m.body("object").id
            R, com = d.xmat[b].reshape(3, 3).copy(), m.body_ipos[b].copy()
            holds = [_hold(loaded, np.r_[R @ u, 0.0, 0.0, 0.0], BOX_CAP) for u in units]
            loaded.ratchet.release()  # the analysis maps read the grasp without the ratchet
            grasps = {col: grasp_from_mujoco(m, d, **kw) for col, kw in MODELS.items()}
            for a, u, hold in zip(angles, units, holds, strict=True):
                d_obj = np.r_[u, np.cross(com, u)]  # the force through the centre of mass
                pred = _predictions(grasps, d_obj, loaded.commands, BOX_CAP)
                angle = round(float(np.degrees(a)), 4)
                rows.append({"scene": "barrett_box", "map": f"{plane}, {tag}",
                             "angle_deg": angle, **hold, **pred})  # fmt: skip
            if log:
                log(f"barrett_box {plane}, {tag}: {time.perf_counter() - t:.0f} s")
    return rows


def cube_rows(log: Any = None) -> list[dict[str, Any]]:
    """The ``barrett_cube`` rows: per load and thumb command; the grasp is read with the
    ratchet on, and the force acts through the object origin, as ``barrett.cube`` does."""
    rows = []
    for tau3 in CUBE_TAUS:
        t = time.perf_counter()
        pre = [0.0, 0.1, 0.1, tau3]
        loaded, ok = seated("barrett_cube", pre, CUBE_SEAT)
        m, d = loaded
        b = m.body("object").id
        R, com = d.xmat[b].reshape(3, 3).copy(), m.body_ipos[b].copy()
        grasps = {col: grasp_from_mujoco(m, d, **kw) for col, kw in MODELS.items()}
        for name, (dw, cap) in CUBE_LOADS.items():
            f, tq = dw[:3], dw[3:]
            if ok:
                hold = _hold(loaded, np.r_[R @ f, R @ (tq + np.cross(-com, f))], cap)
            else:  # the thumb pushed the object out before any load (as barrett.cube)
                hold = {"hold_reason": "slid out at rest"}
                hold.update({col: 0.0 for col in VARIANTS} | {f"{c}_capped": 0 for c in VARIANTS})
            pred = _predictions(grasps, dw, pre, cap)
            rows.append({"scene": "barrett_cube", "map": name, "tau3_Nm": tau3, **hold, **pred})
        if log:
            log(f"barrett_cube tau3 {tau3:g}: {time.perf_counter() - t:.0f} s")
    return rows


def _ramp_summaries(dirs: list[Path]) -> dict[str, dict[str, Any]]:
    """``barrett_box`` and ``barrett_cube`` experiment summaries from the first of ``dirs``
    that has each (absent: not in the result)."""
    out = {}
    for name in ("barrett_box", "barrett_cube"):
        for folder in dirs:
            path = folder / f"{name}_summary.json"
            if path.exists():
                out[name] = {"path": str(path), **json.loads(path.read_text())}
                break
    return out


def _add_ramp(rows: list[dict[str, Any]], ramp: dict[str, dict[str, Any]]) -> None:
    """The experiments' ramp value (distance rule) of each row's direction, where the
    summary has that direction."""
    for r in rows:
        s = ramp.get(r["scene"])
        if s is None:
            continue
        if r["scene"] == "barrett_box":
            entry = s.get(r["map"])
            k = r["angle_deg"] / (360.0 / s["directions"])
            if entry is None or abs(k - round(k)) > 1e-6:
                continue
            r["ramp"] = entry["values"]["sim"][int(round(k))]
            r["ramp_capped"] = entry["capped"]["sim"][int(round(k))]
        else:
            taus = [round(x, 6) for x in s["tau3"]]
            if r["tau3_Nm"] in taus and r["map"] in s:
                r["ramp"] = s[r["map"]]["sim"][taus.index(r["tau3_Nm"])]
                r["ramp_capped"] = 0  # the cube's summary keeps no capped flags


def read_rows(path: Path) -> list[dict[str, Any]]:
    """The rows of a ``holds.csv`` (numbers as floats; empty cells left out)."""
    text = {"scene", "map", "hold_reason", "unit_status", "mujoco_status"}
    with path.open(newline="") as fh:
        return [{k: v if k in text else float(v) for k, v in r.items() if v != ""}
                for r in csv.DictReader(fh)]  # fmt: skip


def _map(rows: list[dict[str, Any]], col: str) -> ResistibleMap:
    """One column of rows as a map (angles: the rows' order) for :func:`agreement`."""
    v = np.array([r.get(col, np.nan) for r in rows], dtype=float)
    c = np.array([bool(r.get(f"{col}_capped", 0)) for r in rows])
    return ResistibleMap(np.arange(len(rows), dtype=float), v, c, 0.0, "", col)


def summarise(rows: list[dict[str, Any]], ref: str = "hold") -> dict[str, dict[str, Any]]:
    """Per map: each model's and the ramp's :func:`agreement` with the column ``ref`` (a
    hold variant), with how many of their values are 0; each model's agreement with the
    ramp over the same directions (``<model>_vs_ramp``); the median ratio to the main hold
    of the ramp and of the other hold variants over directions finite and positive in
    both; how many directions failed a load below the main hold (``hold_fails_below``)."""
    out: dict[str, dict[str, Any]] = {}
    for key in dict.fromkeys((r["scene"], r["map"]) for r in rows):
        sub = [r for r in rows if (r["scene"], r["map"]) == key]
        base = _map(sub, ref)
        res: dict[str, Any] = {"directions": len(sub)}
        for col in (*MODELS, "ramp"):
            res[col] = agreement(_map(sub, col), base)
            res[col]["zero"] = int(np.sum(_map(sub, col).magnitudes == 0))
        for col in MODELS:
            res[f"{col}_vs_ramp"] = agreement(_map(sub, col), _map(sub, "ramp"))
        hold = _map(sub, "hold")
        for col in ("ramp", *VARIANTS):
            other = _map(sub, col)
            both = ~hold.capped & ~other.capped & (hold.magnitudes > 0) & (other.magnitudes > 0)
            ratio = other.magnitudes[both] / hold.magnitudes[both]
            res[f"{col}_over_hold"] = float(np.median(ratio)) if both.any() else float("nan")
        res["fails_below"] = sum(r.get("hold_fails_below") is not None for r in sub)
        out[f"{key[0]}: {key[1]}"] = res
    return out


def _ramp_reference(ramp: dict[str, dict[str, Any]]) -> dict[str, dict[str, float]]:
    """The experiments' own median ``|ln(pred / ramp)|`` (their summaries: box per map, the
    unit model by refinement; cube per load as ``barrett.cube`` measures it); NaN for a
    prediction a summary lacks."""
    labels = {"unit (refinement)": "refinement", "mujoco": "modesearch, mujoco"}
    nan = {"median_abs_log_ratio": float("nan")}
    out = {}
    for k, v in ramp.get("barrett_box", {}).items():
        if isinstance(v, dict) and "agreement" in v:
            out[f"barrett_box: {k}"] = {
                col: v["agreement"].get(label, nan)["median_abs_log_ratio"]
                for col, label in labels.items()
            }
    for k, v in ramp.get("barrett_cube", {}).items():
        if isinstance(v, dict) and "sim" in v:
            out[f"barrett_cube: {k}"] = {col: _cube_mlr(v, label) for col, label in labels.items()}
    return out


def _cube_mlr(load: dict[str, Any], label: str) -> float:
    """A ``barrett_cube`` summary's median ``|ln(pred / ramp)|`` of one load for the
    prediction ``label`` (a summary with refinement alone keeps it at the load's level)."""
    entry = load.get(label)
    if isinstance(entry, dict):
        return float(entry["median_abs_log_ratio"])
    if label == "refinement" and "median_abs_log_ratio" in load:
        return float(load["median_abs_log_ratio"])
    return float("nan")


def _cell(a: dict[str, Any], counts: bool = True) -> str:
    """An agreement as "dir / mlr (finite, zero)" (counts=False: without the counts)."""
    cell = f"{a['direction_agreement']:.2f} / {a['median_abs_log_ratio']:.3f}"
    return cell + (f" ({a['finite']}, {a['zero']})" if counts else "")


def _table(summary: dict[str, dict[str, Any]], reference: dict[str, dict[str, float]]) -> str:
    """The agreement with the main hold as a Markdown table (dir: direction agreement;
    mlr: median |ln(pred / hold)|; finite: directions in the mlr; zero: predictions 0),
    with the models' agreement with the ramp over the same directions and the
    experiments' own (their directions, the unit model by refinement)."""
    lines = ["| map | n | unit vs hold: dir / mlr (finite, zero) | mujoco vs hold | unit vs ramp "
             "| mujoco vs ramp | ramp / hold (median) | experiment vs ramp: unit (refinement), "
             "mujoco mlr |", "|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for key, s in summary.items():
        ref = reference.get(key)
        ref_cell = "-" if ref is None else (f"{ref['unit (refinement)']:.3f}, "
                                            f"{ref['mujoco']:.3f}")  # fmt: skip
        lines.append(f"| {key} | {s['directions']} | {_cell(s['unit'])} | {_cell(s['mujoco'])} "
                     f"| {_cell(s['unit_vs_ramp'], False)} | {_cell(s['mujoco_vs_ramp'], False)} "
                     f"| {s['ramp_over_hold']:.2f} | {ref_cell} |")  # fmt: skip
    return "\n".join(lines)


def _variants_table(rows: list[dict[str, Any]]) -> str:
    """The hold variants: each model's agreement with them, their median ratio to the main
    hold, and the directions where a load below the main hold was not held."""
    cols = [c for c in VARIANTS if c != "hold"]
    head = " | ".join(f"unit vs {c}: dir / mlr | mujoco vs {c} | {c} / hold" for c in cols)
    lines = [f"| map | {head} | fails below |", "|---" * (2 + 3 * len(cols)) + "|"]
    main = summarise(rows)
    per = {c: summarise(rows, c) for c in cols}
    for key, s in main.items():
        cells = []
        for c in cols:
            u, mj = per[c][key]["unit"], per[c][key]["mujoco"]
            cells.append(f"{u['direction_agreement']:.2f} / {u['median_abs_log_ratio']:.3f} | "
                         f"{mj['direction_agreement']:.2f} / {mj['median_abs_log_ratio']:.3f} | "
                         f"{s[f'{c}_over_hold']:.2f}")  # fmt: skip
        lines.append(f"| {key} | {' | '.join(cells)} | {s['fails_below']} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = ArgumentParser(prog="python -m ihm.experiments.holds",
                        description="Static holds on the Barrett experiments' grasps against "
                        "the grasp model's predictions (module doc).")  # fmt: skip
    ap.add_argument("--out", type=Path, default=Path("docs/experiments"))
    ap.add_argument("--directions", type=int, default=12, help="per box map (default 12)")
    ap.add_argument("--ramp", type=Path, nargs="*",
                    default=[Path("runs/exp"), Path("docs/experiments")],
                    help="folders searched in order for the *_summary.json")  # fmt: skip
    ap.add_argument("--only", choices=("box", "cube"), help="one scene only")
    ap.add_argument("--from-csv", type=Path, metavar="CSV",
                    help="print the tables of a holds.csv written before; run nothing")  # fmt: skip
    args = ap.parse_args(argv)
    if args.directions < 1:
        ap.error(f"--directions must be >= 1, got {args.directions}")
    t0 = time.perf_counter()

    def log(msg: str) -> None:
        print(f"[{time.perf_counter() - t0:6.0f} s] {msg}", file=sys.stderr, flush=True)

    ramp = _ramp_summaries(args.ramp)
    if args.from_csv is not None:
        rows = read_rows(args.from_csv)
    else:
        rows = []
        if args.only in (None, "box"):
            rows += box_rows(args.directions, log)
        if args.only in (None, "cube"):
            rows += cube_rows(log)
        _add_ramp(rows, ramp)
        args.out.mkdir(parents=True, exist_ok=True)
        path = write_csv(args.out / "holds.csv", rows, COLUMNS)
        print(f"wrote {path} ({len(rows)} rows) in {time.perf_counter() - t0:.0f} s")
    print("experiments' ramp from " + (", ".join(v["path"] for v in ramp.values()) or "nowhere"))
    print(_table(summarise(rows), _ramp_reference(ramp)))
    print()
    print(_variants_table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
