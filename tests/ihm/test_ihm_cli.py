"""``python -m ihm`` and its pictures: list, show, PNG and rerun output, errors.

The PNG checks can fail: the image must have the requested size, must not
be blank, and the contact decorations must change it (a render with the
contacts differs from one without, by pixels of the arrow colour).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import matplotlib.image
import mujoco
import numpy as np
import pytest
from conftest import THESIS_SCENES

import ihm
from ihm import scenes
from ihm.__main__ import main
from ihm.render import ARROW_RGBA, RenderError, render_png
from ihm.rerun_log import log_scene

ROOT = Path(__file__).resolve().parents[2]
PREFERRED = THESIS_SCENES

# Two fingers squeeze a box: a slide finger and a hinge finger, motors, no lights
# (the renderer brightens the headlight). A complete scene file: object, keyframe
# 'init', ihm_preload, ihm_hand, ihm_about.
TOY_SCENE = """
<mujoco model="toy">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="0.001" cone="elliptic" integrator="implicitfast" noslip_iterations="20"/>
  <custom>
    <numeric name="ihm_preload" data="5.0 -0.25"/>
    <text name="ihm_hand" data="toy"/>
    <text name="ihm_about" data="two fingers squeeze a box (test scene)"/>
  </custom>
  <default><geom contype="0" conaffinity="1" mass="0.05"/></default>
  <worldbody>
    <body name="left" pos="-0.05 0 0" gravcomp="1">
      <joint name="lslide" type="slide" axis="1 0 0" damping="1"/>
      <geom name="lpad" type="capsule" fromto="0 0 -0.02 0 0 0.02" size="0.01"/>
    </body>
    <body name="right" pos="0.05 0 0" gravcomp="1">
      <joint name="rhinge" type="hinge" axis="0 1 0" pos="0 0 -0.05" damping="0.1"/>
      <geom name="rpad" type="capsule" fromto="0 0 -0.02 0 0 0.02" size="0.01"/>
    </body>
    <body name="object">
      <freejoint name="object"/>
      <geom name="box" type="box" size="0.03 0.03 0.03" mass="0.1" contype="1" conaffinity="0"
            friction="1" rgba="0.3 0.5 0.8 1"/>
    </body>
  </worldbody>
  <actuator>
    <motor name="lm" joint="lslide"/>
    <motor name="rm" joint="rhinge"/>
  </actuator>
  <keyframe><key name="init" qpos="-0.005 0  0 0 0 1 0 0 0"/></keyframe>
</mujoco>
"""


def _arrow_pixels(img: np.ndarray) -> int:
    """Pixels of the arrows' red, also where blended over what hides them."""
    rgb = img[..., :3].astype(float)
    if rgb.max() > 1.0:
        rgb = rgb / 255.0
    return int((rgb[..., 0] - rgb[..., 1:].max(axis=-1) > 0.3).sum())


def _run(*args: str) -> subprocess.CompletedProcess[str]:
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
    }
    return subprocess.run(
        [sys.executable, "-m", "ihm", *args],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )


@pytest.fixture(scope="module")
def toy_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("scenes")
    (d / "toy.xml").write_text(TOY_SCENE)
    return d


@pytest.fixture(scope="module")
def toy(toy_dir: Path):
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(scenes, "SCENES_DIR", toy_dir)
        model, data = scenes.load_scene("toy")
    return model, data, ihm.grasp_from_mujoco(model, data)


def _gl_or_skip(exc: RenderError) -> None:
    pytest.skip(f"no offscreen OpenGL here: {exc}")


def test_render_png_draws_the_contacts(toy, tmp_path: Path) -> None:
    model, data, grasp = toy
    assert grasp.m >= 2
    renderer_module = sys.modules[mujoco.Renderer.__module__]
    context_class = getattr(getattr(renderer_module, "gl_context", None), "GLContext", None)
    try:
        with_forces = render_png(model, data, grasp, tmp_path / "f.png", width=320, height=240)
        plain = render_png(
            model, data, grasp, tmp_path / "p.png", width=320, height=240, contacts=False
        )
    except RenderError as exc:
        _gl_or_skip(exc)
    a = matplotlib.image.imread(with_forces)
    b = matplotlib.image.imread(plain)
    assert a.shape[:2] == (240, 320)
    assert a[..., :3].std() > 0.05  # not blank
    changed = np.abs(a[..., :3] - b[..., :3]).max(axis=-1) > 0.1
    assert changed.sum() > 100
    assert ARROW_RGBA[0] - ARROW_RGBA[1:3].max() > 0.5  # what _arrow_pixels looks for
    assert _arrow_pixels(a) > 50
    assert _arrow_pixels(b) < 5
    # MuJoCo's GL context class and the model's visual settings are restored
    assert getattr(getattr(renderer_module, "gl_context", None), "GLContext", None) is context_class
    assert model.vis.global_.offwidth == 640 and model.vis.headlight.ambient[0] == pytest.approx(
        0.1
    )


def test_render_png_bad_camera(toy, tmp_path: Path) -> None:
    model, data, grasp = toy
    with pytest.raises(RenderError, match="no camera named 'nope'"):
        render_png(model, data, grasp, tmp_path / "x.png", camera="nope")


def test_bad_force_scale(toy, tmp_path: Path) -> None:
    model, data, grasp = toy
    for bad in (-1.0, float("nan")):
        with pytest.raises(ValueError, match="force_scale"):
            render_png(model, data, grasp, tmp_path / "x.png", force_scale=bad)
        with pytest.raises(ValueError, match="force_scale"):
            log_scene(model, data, grasp, tmp_path / "x.rrd", force_scale=bad)
        with pytest.raises(SystemExit) as exc:
            main(["show", "toy", "--force-scale", str(bad)])
        assert exc.value.code == 2


def test_log_scene_writes_rrd(toy, tmp_path: Path) -> None:
    model, data, grasp = toy
    path = log_scene(model, data, grasp, tmp_path / "sub" / "toy.rrd")
    assert path.is_file() and path.stat().st_size > 1000
    raw = path.read_bytes()
    for entity in (b"world/contacts/forces", b"world/contacts/points", b"world/geoms/left/lpad"):
        assert entity in raw


def test_log_scene_reads_back_static(toy, tmp_path: Path) -> None:
    """The settled grasp through the rollouts' recorder: everything static, the geoms at
    MuJoCo's poses, one arrow per grasp contact of length force_scale x the force."""
    from rerun.chunk import RrdReader

    model, data, grasp = toy
    path = log_scene(model, data, grasp, tmp_path / "toy.rrd", force_scale=0.01)
    cols: dict[str, dict] = {}
    for chunk in RrdReader(path).stream():
        batch = chunk.to_record_batch()
        assert "step" not in batch.schema.names and "sim_time" not in batch.schema.names
        entity = batch.schema.metadata[b"rerun:entity_path"].decode()
        cols.setdefault(entity, {}).update(batch.to_pydict())
    arrows = np.array(cols["/world/contacts/forces"]["Arrows3D:vectors"][0])
    np.testing.assert_allclose(arrows, 0.01 * grasp.forces_world(), atol=1e-6)
    g = model.geom("lpad").id
    pos = cols["/world/geoms/left/lpad"]["Transform3D:translation"][0][0]
    np.testing.assert_allclose(pos, data.geom_xpos[g], atol=1e-6)


def test_main_show_in_process(toy_dir: Path, tmp_path: Path, monkeypatch, capsys) -> None:
    monkeypatch.setattr(scenes, "SCENES_DIR", toy_dir)
    out = tmp_path / "toy.png"
    try:
        rc = main(["show", "toy", "--out", str(out), "--width", "200", "--height", "150"])
    except RenderError as exc:  # pragma: no cover - only without GL
        _gl_or_skip(exc)
    text = capsys.readouterr()
    if rc == 2 and "OpenGL" in text.err:
        pytest.skip(text.err.strip())
    assert rc == 0, text.err
    assert "equilibrium residuals" in text.out
    assert "left" in text.out and "right" in text.out  # hand links in the table
    assert matplotlib.image.imread(out).shape[:2] == (150, 200)
    work = tmp_path / "work"  # without --out: runs/ihm/, not the current directory
    work.mkdir()
    monkeypatch.chdir(work)
    assert main(["show", "toy", "--width", "200", "--height", "150"]) == 0
    assert "wrote runs/ihm/toy.png" in capsys.readouterr().out
    assert [p.name for p in work.iterdir()] == ["runs"]
    assert (work / "runs" / "ihm" / "toy.png").is_file()
    rc = main(["show", "toy", "--preload", "1", "2", "3"])
    assert rc == 2
    err = capsys.readouterr().err
    assert "needs 2 actuator forces" in err and "Traceback" not in err
    assert main(["list"]) == 0
    assert "two fingers squeeze a box" in capsys.readouterr().out


def _real_scene() -> str:
    known = ihm.available_scenes()
    for name in PREFERRED:
        if name in known:
            return name
    pytest.skip(f"no thesis scene in {scenes.SCENES_DIR} yet (looked for {', '.join(PREFERRED)})")


def test_show_real_scene_subprocess(tmp_path: Path) -> None:
    name = _real_scene()
    png, rrd, bare = tmp_path / "out.png", tmp_path / "out.rrd", tmp_path / "bare.png"
    size = ("--width", "320", "--height", "240")
    proc = _run("show", name, "--out", str(png), "--rrd", str(rrd), *size)
    if proc.returncode == 2 and "OpenGL" in proc.stderr:
        pytest.skip(proc.stderr.strip())
    assert proc.returncode == 0, proc.stderr
    assert "equilibrium residuals" in proc.stdout and "c_n [N]" in proc.stdout
    assert rrd.is_file() and rrd.stat().st_size > 1000
    img = matplotlib.image.imread(png)
    assert img.shape[:2] == (240, 320)
    assert img[..., :3].std() > 0.05  # not blank
    # the same view without contacts: the arrows are what adds the red
    proc = _run("show", name, "--out", str(bare), "--no-contacts", *size)
    assert proc.returncode == 0, proc.stderr
    plain = matplotlib.image.imread(bare)
    assert (np.abs(img[..., :3] - plain[..., :3]).max(axis=-1) > 0.1).sum() > 50
    assert _arrow_pixels(img) > _arrow_pixels(plain) + 30


def test_unknown_scene_exits_2() -> None:
    proc = _run("show", "no_such_scene")
    assert proc.returncode == 2
    assert "unknown scene 'no_such_scene'" in proc.stderr
    assert "Traceback" not in proc.stderr
    for name in ihm.available_scenes():
        assert name in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


def test_list_prints_each_scene() -> None:
    proc = _run("list")
    assert proc.returncode == 0, proc.stderr
    for name in ihm.available_scenes():
        assert name in proc.stdout
