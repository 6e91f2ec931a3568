"""``python -m ihm.experiments.table [DIR]``: the experiments' figures, both models side by
side, as a Markdown table read from the ``*_summary.json`` files in ``DIR`` (default
``docs/experiments``; written by ``python -m ihm.experiments NAME ...``).

One row per figure (a resistible-force map, or a sweep of one load): for the thesis' unit
springs (``refinement``; ``barrett_flask``: ``refinement`` at 2 levels) and for MuJoCo's
stiffness (``modesearch`` on ``grasp_from_mujoco(..., compliance="mujoco")``, contacts
preloaded with the settled forces), the direction agreement (maps: the fraction of the
directions answered by both that are finite in both or capped in both; sweeps: the
fraction of loads where both are zero or both positive) and the median
``|ln(pred / sim)|`` over the values finite and positive in both
(:func:`ihm.sim_maps.agreement`). A figure meets the targets at agreement >= 0.9 and
median <= 0.15.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Any

__all__ = ["AGREEMENT_TARGET", "LOG_RATIO_TARGET", "figures", "markdown"]

AGREEMENT_TARGET = 0.9
LOG_RATIO_TARGET = 0.15
MUJOCO = "modesearch, mujoco"

#: (figure, summary file, key path to the entry that holds both models, unit label)
MAPS = [
    ("barrett_box xy, no preload", "barrett_box", ("xy, no preload",), "refinement"),
    ("barrett_box xy, preload 0.1 N m", "barrett_box", ("xy, preload 0.1 N m",), "refinement"),
    ("barrett_box xz, no preload", "barrett_box", ("xz, no preload",), "refinement"),
    ("barrett_box xz, preload 0.1 N m", "barrett_box", ("xz, preload 0.1 N m",), "refinement"),
    ("barrett_box_3d xy, finger 1", "barrett_box_3d", ("xy map, finger 1",), "refinement"),
    ("barrett_box_3d xy, finger 2", "barrett_box_3d", ("xy map, finger 2",), "refinement"),
    ("barrett_flask xy, no preload", "barrett_flask", ("xy, no preload",),
     "refinement, 2 levels"),
    ("barrett_flask xy, 0.1 N m", "barrett_flask", ("xy, 0.1 N m per finger",),
     "refinement, 2 levels"),
]  # fmt: skip
SWEEPS = ["force +z [N]", "torque about +x [N m]", "torque about -x [N m]"]


def _entry(path: Path) -> dict[str, Any] | None:
    return json.loads(path.read_text()) if path.is_file() else None


def _fmt(x: float | None) -> str:
    return "-" if x is None or not math.isfinite(x) else f"{x:.2f}"


def _meets(agree: float | None, med: float | None) -> bool:
    return (agree is not None and med is not None and math.isfinite(agree)
            and math.isfinite(med) and agree >= AGREEMENT_TARGET
            and med <= LOG_RATIO_TARGET)  # fmt: skip


def _pairs(values: list[tuple[float, float]]) -> tuple[float, float]:
    """(agreement, median |ln|) of (pred, sim) pairs: zero in both or positive in both."""
    agree = sum((p > 0) == (s > 0) for p, s in values) / max(1, len(values))
    logs = sorted(abs(math.log(p / s)) for p, s in values if p > 0 and s > 0)
    if not logs:
        return agree, float("nan")
    n = len(logs)
    med = logs[n // 2] if n % 2 else 0.5 * (logs[n // 2 - 1] + logs[n // 2])
    return agree, med


def figures(folder: str | Path = "docs/experiments") -> list[dict[str, Any]]:
    """One record per figure: ``figure``, and ``unit`` / ``mujoco`` each ``(agreement,
    median |ln(pred/sim)|)`` or None where the summary lacks that model."""
    folder = Path(folder)
    rows: list[dict[str, Any]] = []
    for name, stem, keys, unit in MAPS:
        s = _entry(folder / f"{stem}_summary.json")
        ag = None if s is None else s.get(keys[0], {}).get("agreement", {})
        row: dict[str, Any] = {"figure": name}
        for model, label in (("unit", unit), ("mujoco", MUJOCO)):
            a = None if ag is None else ag.get(label)
            row[model] = None if a is None else (a["direction_agreement"],
                                                 a["median_abs_log_ratio"])  # fmt: skip
        rows.append(row)
    cube = _entry(folder / "barrett_cube_summary.json")
    for load in SWEEPS:
        row = {"figure": f"barrett_cube {load}, thumb swept", "unit": None, "mujoco": None}
        if cube is not None and load in cube:
            c = cube[load]
            for model, label in (("unit", "refinement"), ("mujoco", MUJOCO)):
                if isinstance(c.get(label), dict):
                    row[model] = _pairs(list(zip(c[label]["values"], c["sim"], strict=True)))
        rows.append(row)
    b3 = _entry(folder / "barrett_box_3d_summary.json")
    row = {"figure": "barrett_box_3d +x, finger 1 and finger 2", "unit": None, "mujoco": None}
    if b3 is not None:
        for model, label in (("unit", "refinement"), ("mujoco", MUJOCO)):
            if label in b3.get("finger 1", {}):
                row[model] = _pairs([(b3[c][label]["value"], b3[c]["sim"]["value"])
                                     for c in ("finger 1", "finger 2")])  # fmt: skip
    rows.append(row)
    tb = _entry(folder / "tendon_box_summary.json")
    rows.append({"figure": "tendon_box xy, distal tendon", "unit": None, "mujoco": None})
    rows.append({"figure": "tendon_box torque +-x, both cases", "unit": None, "mujoco": None})
    if tb is not None:
        xy = tb["xy_map"]
        a = xy["agreement"]
        rows[-2]["unit"] = (a["direction_agreement"], a["median_abs_log_ratio"])
        m = xy.get(f"agreement {MUJOCO}")
        if m is not None:
            rows[-2]["mujoco"] = (m["direction_agreement"], m["median_abs_log_ratio"])
        t = tb["torque_Nm"]
        for model, label in (("unit", "refinement"), ("mujoco", MUJOCO)):
            if all(label in t[c] for c in t):
                rows[-1][model] = _pairs([(t[c][label][s]["value"], t[c]["sim"][s]["value"])
                                          for c in t for s in ("+x", "-x")])  # fmt: skip
    return rows


def markdown(rows: list[dict[str, Any]]) -> str:
    """The table of :func:`figures`, with a last line counting the figures that meet the
    targets per model."""
    out = ["| figure | unit springs: agreement | median \\|ln\\| | MuJoCo's stiffness: "
           "agreement | median \\|ln\\| |", "|---|---|---|---|---|"]  # fmt: skip
    met = {"unit": 0, "mujoco": 0}
    for r in rows:
        cells = [r["figure"]]
        for model in ("unit", "mujoco"):
            v = r[model]
            ok = v is not None and _meets(*v)
            met[model] += ok
            a, m = (None, None) if v is None else v
            star = " (meets)" if ok else ""
            cells += [_fmt(a), _fmt(m) + star]
        out.append("| " + " | ".join(cells) + " |")
    out.append(f"\nMeeting both targets (agreement >= {AGREEMENT_TARGET}, median <= "
               f"{LOG_RATIO_TARGET}): unit springs {met['unit']} of {len(rows)}, MuJoCo's "
               f"stiffness {met['mujoco']} of {len(rows)}.")  # fmt: skip
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    print(markdown(figures(args[0] if args else "docs/experiments")))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
