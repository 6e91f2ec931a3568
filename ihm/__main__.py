"""``python -m ihm``: list the thesis' grasp scenes, settle one and look at its contacts.

Examples::

    python -m ihm list
    python -m ihm show barrett_box                      # table + runs/ihm/barrett_box.png
    python -m ihm show barrett_box --out box.png --rrd box.rrd
    python -m ihm show barrett_box --preload 0.3 0.3 0.3 0
    python -m ihm map barrett_box --plane xy --workers 2 --nonbackdrivable
    python -m ihm batch barrett_box box.jsonl --directions 36   # for python -m stability.batch
    python -m ihm show my/gripper.xml --object parcel   # your own MJCF file, its free body
    python -m ihm map my/gripper.xml --object parcel --method sim modesearch --plane xz

SCENE is one of our scenes' names (``python -m ihm list``) or an MJCF file's path (it ends
in ``.xml`` or holds a ``/``); ``--object`` names the grasped free body (default
``object``). Without ``--preload`` a scene settles with its ``ihm_preload`` forces, else
with its ``init`` keyframe's controls (zeros without a keyframe; :mod:`ihm.scenes`).

Errors (unknown scene or file, a file MuJoCo cannot compile, no such free body, wrong
preload length, a grasp that does not settle, no OpenGL context) print one line to
stderr and exit with status 2.
"""

from __future__ import annotations

import os

# Headless EGL unless the user chose a backend (osmesa, glfw). MuJoCo fixes its
# GL backend when first imported, which `python -m ihm` does (ihm/__init__)
# before this line runs; ihm.render reads MUJOCO_GL again when it creates the
# context, so setting it here still takes effect.
os.environ.setdefault("MUJOCO_GL", "egl")

import argparse
import math  # noqa: E402
import sys  # noqa: E402
from collections.abc import Sequence  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from stability import GraspError  # noqa: E402
from stability.cli import ArgumentParser

from . import scenes  # noqa: E402
from .contact_law import CONTACT_LAWS  # noqa: E402
from .contacts import SceneGrasp, grasp_from_mujoco  # noqa: E402

PROG = "python -m ihm"
OUT_DIR = Path("runs") / "ihm"  # where show and map write by default (git ignores runs/)


def _parser() -> argparse.ArgumentParser:
    """The CLI's parser: one subcommand each for list, show, map and batch."""
    parser = ArgumentParser(
        prog=PROG,
        description="Grasp scenes of the thesis on MuJoCo: list them, or settle one and "
        "show its contacts and forces (table, PNG, rerun recording).",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _add_list(sub)
    _add_show(sub)
    _add_map(sub)
    _add_batch(sub)
    return parser


def _add_list(sub: Any) -> None:
    """The ``list`` subcommand (no arguments)."""
    sub.add_parser(
        "list",
        help="list the scenes in assets/scenes with their descriptions",
        description="List the scenes in assets/scenes, one per line: name and ihm_about.",
    )


def _add_scene(cmd: argparse.ArgumentParser) -> None:
    """The SCENE argument (a name or a file's path) and ``--object``, the grasped body."""
    cmd.add_argument("scene", metavar="SCENE", help="scene name (see 'python -m ihm list') or "
                     "the path of an MJCF file (ends in .xml or holds a /)")  # fmt: skip
    cmd.add_argument("--object", dest="object_body", default="object", metavar="BODY",
                     help="the grasped free body (default: object)")  # fmt: skip


def _add_show(sub: Any) -> None:
    """The ``show`` subcommand: a scene, the commands it settles with, the PNG and .rrd."""
    show = sub.add_parser(
        "show",
        help="settle a scene's grasp; print its contacts; write a PNG (and .rrd)",
        description="Load SCENE, close the hand with the commanded actuator forces until the "
        "grasp is at rest, and print per contact the hand link, the point in the object frame "
        "[mm], the normal and tangential force of the hand on the object [N] and the friction "
        "coefficient, with the settle time and the equilibrium residuals. Writes a PNG with "
        "contact points (yellow) and force arrows (red, from the point along the force of "
        "the hand on the object), and optionally a rerun recording.",
    )
    _add_scene(show)
    show.add_argument(
        "--out",
        type=Path,
        metavar="PATH.png",
        help=f"PNG to write (default: {OUT_DIR}/SCENE.png; a file's stem for a path)",
    )
    show.add_argument(
        "--rrd", type=Path, metavar="PATH.rrd", help="also write a rerun recording to this file"
    )
    show.add_argument(
        "--preload",
        type=float,
        nargs="+",
        metavar="F",
        help="commanded actuator forces, one per actuator, in each actuator's unit "
        "(N m for joint motors, N for tendons); default: the scene's ihm_preload, else its "
        "init keyframe's controls",
    )
    show.add_argument("--width", type=int, default=640, help="image width [px] (default 640)")
    show.add_argument("--height", type=int, default=480, help="image height [px] (default 480)")
    show.add_argument(
        "--force-scale",
        type=float,
        metavar="M_PER_N",
        help="arrow length per newton [m/N] (default: largest force 0.8 object radii long)",
    )
    show.add_argument(
        "--no-contacts",
        action="store_true",
        help="draw the scene without contact points and force arrows (same view)",
    )


def _add_map(sub: Any) -> None:
    """The ``map`` subcommand: the :class:`ihm.sim_maps.MapSpec` fields, the methods and
    their options, the workers and where the CSV and PNG go."""
    mp_ = sub.add_parser(
        "map",
        help="resistible force per direction in a plane: MuJoCo and/or a stability method "
        "(CSV + polar PNG)",
        description="Settle SCENE with the given commands, then per direction in PLANE (world "
        "axes, 1-degree spacing by default) ramp a force on the object until it moves 2 mm "
        "(ihm.resistance): the largest force held, capped at --cap; or the stability method's "
        "MaxDisturbance on the settled grasp with the object's weight as base load. Several "
        "--method and --preload sets are overlaid on one chart. Writes OUT/SCENE_PLANE.csv "
        "and .png.",
    )
    _add_scene(mp_)
    mp_.add_argument("--plane", default="xy", help="two force axes, e.g. xy, xz, yz (default xy)")
    mp_.add_argument(
        "--method",
        nargs="+",
        default=["sim"],
        help="one or more of sim (MuJoCo), modesearch, refinement, iterative, no_mdp, exact, "
        "gws (default sim); maps are overlaid",
    )
    mp_.add_argument(
        "--time-limit", type=float, default=None, help="seconds per solve (stability methods)"
    )
    mp_.add_argument("--directions", type=int, default=360, help="directions (default 360)")
    mp_.add_argument(
        "--frame",
        default="world",
        help="axes of --plane: world (palm frame, default) or object (the object's axes at "
        "rest: the thesis' axes as each scene documents them)",
    )
    mp_.add_argument(
        "--preload",
        type=float,
        nargs="+",
        action="append",
        metavar="F",
        help="commanded actuator forces (one per actuator); repeat for several maps; "
        "default: the scene's ihm_preload, else its init keyframe's controls",
    )
    mp_.add_argument(
        "--nonbackdrivable",
        action="store_true",
        help="ratchet the motor joints and actuated tendons (ihm.ratchet)",
    )
    mp_.add_argument(
        "--seat",
        type=float,
        nargs="+",
        metavar="F",
        help="with --nonbackdrivable: settle with these commands first, ratchet, then load "
        "with --preload (actuators commanded 0 stay as passive, nonbackdrivable supports)",
    )
    mp_.add_argument(
        "--normal-uncertainty",
        type=float,
        default=None,
        metavar="DEG",
        help="contact-normal uncertainty eta [deg] for the refinement method (default 0)",
    )
    mp_.add_argument(
        "--compliance",
        choices=("unit", "mujoco"),
        default="unit",
        help="the stability methods' springs: unit (the thesis', default) or mujoco "
        "(MuJoCo's contact, servo and spring stiffness; ihm.grasp_from_mujoco)",
    )
    mp_.add_argument("--motion-limit", type=float, nargs=2, metavar=("SHIFT", "TURN"),
                     help="with --compliance mujoco: the stability methods answer the largest "
                     "load held with the object's centre of mass within SHIFT [m] and its "
                     "rotation within TURN [rad] of the settled state (default 0.002 0.05, "
                     "where the simulated ramp stops; inf inf: free)")  # fmt: skip
    mp_.add_argument("--near", type=float, default=0.0, metavar="D",
                     help="with --compliance mujoco: hand points within D [m] of the object that "
                     "do not touch it yet become contacts at their gap (ihm.near; default 0, "
                     "none; the experiments use 0.002)")  # fmt: skip
    mp_.add_argument("--contact-law", choices=CONTACT_LAWS, default="slope",
                     help="with --compliance mujoco: each contact a linear spring of its slope "
                     "at the state (slope, default) or MuJoCo's static law, which stiffens as "
                     "the contact presses, as a convex piecewise-linear spring (fitted, "
                     "ihm.contact_law; the experiments use it)")  # fmt: skip
    mp_.add_argument("--cap", type=float, default=10.0, help="largest force tried [N] (10)")
    mp_.add_argument("--workers", type=int, default=1, help="processes (default 1); with "
                     "--ray, the CPUs of a new local Ray cluster")  # fmt: skip
    mp_.add_argument("--ray", metavar="ADDRESS", help="run the directions as Ray tasks: 'auto' "
                     "(the running cluster, else a new local one), 'local' or a cluster address "
                     "(needs pip install -e '.[ray]')")  # fmt: skip
    mp_.add_argument("--out", type=Path, default=OUT_DIR, help=f"output folder (default {OUT_DIR})")
    mp_.add_argument("--no-progress", action="store_true", help="no progress bar")


def _add_batch(sub: Any) -> None:
    """The ``batch`` subcommand: a map's queries as a file for ``python -m stability.batch``."""
    bt = sub.add_parser(
        "batch",
        help="write a map's queries as a batch file for python -m stability.batch",
        description="Settle SCENE and write one MaxDisturbance query row per direction of its "
        "resistible-force map (the queries of 'map --method M') to OUT, for "
        "'python -m stability.batch OUT RESULTS' (local processes or a Ray cluster).",
    )
    _add_scene(bt)
    bt.add_argument("out", type=Path, help="query file to write (JSON lines)")
    bt.add_argument("--plane", default="xy", help="two force axes (default xy)")
    bt.add_argument("--directions", type=int, default=36, help="directions (default 36)")
    bt.add_argument("--frame", default="world", help="axes of --plane: world or object")
    bt.add_argument("--method", default="modesearch", help="stability method written into "
                    "each row (default modesearch)")  # fmt: skip
    bt.add_argument("--preload", type=float, nargs="+", metavar="F",
                    help="commanded actuator forces (default: the scene's preload)")  # fmt: skip
    bt.add_argument("--nonbackdrivable", action="store_true", help="ratchet the motor joints")
    bt.add_argument("--cap", type=float, default=10.0, help="largest force asked [N] (10)")


def _cmd_list() -> int:
    names = scenes.available_scenes()
    if not names:
        print(f"no scenes in {scenes.SCENES_DIR}")
        return 0
    width = max(len(n) for n in names)
    for name in names:
        try:
            about = scenes.scene_about(name)
        except ValueError as exc:  # a scene that does not compile still gets listed
            about = f"(does not compile: {str(exc).splitlines()[0]})"
        print(f"{name:<{width}}  {about}")
    return 0


def contact_table(model: mujoco.MjModel, grasp: SceneGrasp) -> str:
    """Per contact: hand link, point in the object frame [mm], c_n [N], |c_t| [N], mu."""
    links = [model.body(int(b)).name or f"body {b}" for b in grasp.hand_bodies]
    w = max(9, *(len(s) for s in links))
    head = f"{'#':>2}  {'hand link':<{w}}  {'x, y, z in object frame [mm]':>28}  "
    head += f"{'c_n [N]':>8}  {'|c_t| [N]':>9}  {'mu':>5}  {'|c_t|/c_n':>9}"
    rows = [head, "-" * len(head)]
    for k, (link, p, c, mu) in enumerate(
        zip(links, grasp.points, grasp.forces, grasp.mu, strict=True)
    ):
        ct = float(np.hypot(c[1], c[2]))
        ratio = f"{ct / c[0]:9.3f}" if c[0] > 1e-9 else f"{'-':>9}"
        xyz = ", ".join(f"{1e3 * v:7.2f}" for v in p)
        rows.append(f"{k:>2}  {link:<{w}}  {xyz:>28}  {c[0]:8.3f}  {ct:9.3f}  {mu:5.2f}  {ratio}")
    return "\n".join(rows)


def _cmd_show(args: argparse.Namespace) -> int:
    from .render import render_png  # after MUJOCO_GL is set (it is, at the top)

    loaded = scenes.load_scene(args.scene, preload=args.preload, object_body=args.object_body)
    model, data, info = loaded.model, loaded.data, loaded.settle_info
    grasp = grasp_from_mujoco(model, data, args.object_body)
    about = scenes.scene_about(args.scene)
    print(f"scene {args.scene}" + (f": {about}" if about else ""))
    if info is not None:
        print(
            f"settled in {info.time_s:.3f} s simulated ({info.wall_s:.2f} s wall, {info.steps} "
            f"steps, {info.rounds} round(s)), max |qvel| = {info.max_vel:.2g}"
        )
    cmd = ", ".join(
        f"{n} = {f:.4g}" for n, f in zip(grasp.actuator_names, grasp.commands, strict=True)
    )
    print(f"actuator forces: {cmd}")
    print(f"{grasp.m} contacts (forces of the hand on the object):")
    print(contact_table(model, grasp))
    res = grasp.equilibrium_residuals()
    print(
        f"equilibrium residuals: object max|G c + w_g| = {res['object']:.3g} [N, N m], "
        f"hand max|J^T c - R f| = {res['hand']:.3g} [N m]"
    )
    out = args.out if args.out is not None else OUT_DIR / f"{scenes.scene_label(args.scene)}.png"
    png = render_png(
        model,
        data,
        grasp,
        out,
        width=args.width,
        height=args.height,
        force_scale=args.force_scale,
        contacts=not args.no_contacts,
    )
    print(f"wrote {png}")
    if args.rrd is not None:
        from .rerun_log import log_scene

        rrd = log_scene(model, data, grasp, args.rrd, force_scale=args.force_scale)
        print(f"wrote {rrd}")
    return 0


def _cmd_map(args: argparse.Namespace) -> int:
    from stability.api import RENAMED_METHODS

    from .sim_maps import MapError, MapSpec, check_options, run

    for i, method in enumerate(args.method):  # old names work, and the user is told once
        if method in RENAMED_METHODS:
            new = RENAMED_METHODS[method]
            print(f"{PROG} map: note: method {method!r} is called {new!r} now", file=sys.stderr)
            args.method[i] = new
    try:
        for method in args.method:
            check_options(args.plane, method, args.directions, args.workers, args.cap, args.frame)
        preloads = args.preload or [None]
        opts: dict[str, float] = {} if args.time_limit is None else {"time_limit": args.time_limit}
        if args.normal_uncertainty is not None:
            if set(args.method) - {"refinement", "sim"}:
                raise MapError("--normal-uncertainty applies to the refinement method only")
            opts["normal_uncertainty"] = float(np.radians(args.normal_uncertainty))
        if args.seat is not None and not args.nonbackdrivable:
            raise MapError("--seat needs --nonbackdrivable (it ratchets the seated grasp)")
        spec = MapSpec(args.scene, args.plane, args.directions, seat=args.seat,
                       nonbackdrivable=args.nonbackdrivable, frame=args.frame,
                       cap=args.cap, object_body=args.object_body, compliance=args.compliance,
                       near=args.near, contact_law=args.contact_law,
                       motion_limit=None if args.motion_limit is None
                       else tuple(args.motion_limit))  # fmt: skip
        for method in args.method:
            spec.check(method, args.workers)
        csv_path, png, walls, agree = run(
            spec, preloads, args.out, methods=args.method, workers=args.workers,
            progress=not args.no_progress, ray=args.ray, **opts,
        )  # fmt: skip
    except (MapError, GraspError, OSError) as exc:  # SceneError is a GraspError
        print(f"{PROG} map: error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {csv_path} and {png} ({', '.join(f'{w:.1f} s' for w in walls)} per map)")
    for label, _, a in agree:
        print(
            f"{label} vs sim: {a['direction_agreement']:.0%} of {a['answered']} directions agree "
            f"on finite vs capped; median |ln(pred/sim)| = {a['median_abs_log_ratio']:.3f} over "
            f"{a['finite']} finite directions"
        )
    import csv

    with csv_path.open() as f:
        failed = [r["label"] for r in csv.DictReader(f) if r["force_N"] == "nan"]
    if failed:
        labels = sorted(set(failed))
        print(f"{len(failed)} direction(s) without an answer (solver error or time-out) in: "
              f"{'; '.join(labels)}")  # fmt: skip
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; returns the exit status (2 on a user-facing error)."""
    from .render import RenderError

    parser = _parser()
    args = parser.parse_args(argv)
    if args.command == "list":
        return _cmd_list()
    if args.command == "map":
        return _cmd_map(args)
    if args.command == "batch":
        from stability.batch import write_rows

        from .sim_maps import MapError, MapSpec, scene_map_rows

        try:
            spec = MapSpec(args.scene, args.plane, args.directions, preload=args.preload,
                           nonbackdrivable=args.nonbackdrivable, frame=args.frame,
                           cap=args.cap, object_body=args.object_body)  # fmt: skip
            rows = scene_map_rows(spec, method=args.method)
            n = write_rows(args.out, rows)
        except (MapError, GraspError, OSError) as exc:
            print(f"{PROG} batch: error: {exc}", file=sys.stderr)
            return 2
        print(f"{n} queries -> {args.out}")
        return 0
    if args.width < 1 or args.height < 1:
        parser.error(f"--width and --height must be positive, got {args.width} x {args.height}")
    force_scale = getattr(args, "force_scale", None)
    if force_scale is not None and not (math.isfinite(force_scale) and force_scale >= 0):
        parser.error(f"--force-scale must be a finite number >= 0 [m/N], got {force_scale}")
    try:
        return _cmd_show(args)
    except (GraspError, RenderError, OSError) as exc:  # SceneError is a GraspError
        print(f"{PROG} show: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
