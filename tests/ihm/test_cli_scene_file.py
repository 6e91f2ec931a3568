"""``python -m ihm show/map/batch PATH.xml --object BODY``: a user's own MJCF file, not one
of ``assets/scenes``, whose grasped body is not called ``object``.

The scene is a two-finger slide gripper with position servos (``kp`` 5000 N/m) squeezing a
0.1 kg box named ``parcel`` (friction 0.5), with an ``init`` keyframe whose controls close
the fingers 2 mm past the box faces and no ``ihm_preload``: it settles with those controls
(about 8 N per finger). Along world x a push goes into a finger, which a position servo
resists stiffly (sim) and the grasp model holds as nonbackdrivable: both reach the 10 N cap.
Along z only friction holds, 2 mu c_n (about 8 N) plus or minus the 0.98 N weight.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from ihm import scenes
from ihm.__main__ import main
from ihm.sim_maps import MapSpec, simulated_map

GRIPPER = """
<mujoco model="slide gripper">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="0.001" cone="elliptic" integrator="implicitfast" noslip_iterations="20"/>
  <default><geom contype="0" conaffinity="1" mass="0.05" friction="0.5"/></default>
  <worldbody>
    <body name="left" pos="-0.05 0 0" gravcomp="1">
      <joint name="lslide" type="slide" axis="1 0 0" damping="5"/>
      <geom name="lpad" type="capsule" fromto="0 0 -0.02 0 0 0.02" size="0.005"/>
    </body>
    <body name="right" pos="0.05 0 0" gravcomp="1">
      <joint name="rslide" type="slide" axis="-1 0 0" damping="5"/>
      <geom name="rpad" type="capsule" fromto="0 0 -0.02 0 0 0.02" size="0.005"/>
    </body>
    <body name="parcel">
      <freejoint/>
      <geom name="box" type="box" size="0.03 0.025 0.025" mass="0.1" contype="1" conaffinity="0"/>
    </body>
  </worldbody>
  <actuator>
    <position name="lservo" joint="lslide" kp="5000" ctrlrange="0 0.03"/>
    <position name="rservo" joint="rslide" kp="5000" ctrlrange="0 0.03"/>
  </actuator>
  KEYFRAME
</mujoco>
"""
KEY = '<keyframe><key name="init" qpos="0.014 0.014  0 0 0 1 0 0 0" ctrl="0.017 0.017"/></keyframe>'


@pytest.fixture
def gripper(tmp_path: Path) -> Path:
    """The scene file, with its ``init`` keyframe, in a folder of its own."""
    path = tmp_path / "scene" / "gripper.xml"
    path.parent.mkdir()
    path.write_text(GRIPPER.replace("KEYFRAME", KEY))
    return path


def _one_error_line(capsys: pytest.CaptureFixture[str], *words: str) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    for w in words:
        assert w in err, err
    return err


def test_show_a_file_scene(gripper: Path, tmp_path: Path, monkeypatch, capsys) -> None:
    png = tmp_path / "g.png"
    rc = main(["show", str(gripper), "--object", "parcel", "--out", str(png),
               "--width", "200", "--height", "150"])  # fmt: skip
    text = capsys.readouterr()
    if rc == 2 and "OpenGL" in text.err:
        pytest.skip(text.err.strip())
    assert rc == 0, text.err
    assert "equilibrium residuals" in text.out
    assert "left" in text.out and "right" in text.out  # hand links in the table
    line = next(s for s in text.out.splitlines() if s.startswith("actuator forces:"))
    forces = [float(part.split("=")[1]) for part in line.split(":", 1)[1].split(",")]
    assert len(forces) == 2 and all(5.0 < f < 11.0 for f in forces)  # kp x ~2 mm, each finger
    assert png.is_file() and png.stat().st_size > 1000
    monkeypatch.chdir(tmp_path)  # without --out: runs/ihm/<the file's stem>.png
    assert main(["show", "scene/gripper.xml", "--object", "parcel", "--no-contacts"]) == 0
    assert (tmp_path / "runs" / "ihm" / "gripper.png").is_file()


def test_map_a_file_scene_sim_and_model_agree(gripper: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "maps"
    args = ["--method", "sim", "modesearch", "--plane", "xz", "--directions", "4"]
    rc = main(["map", str(gripper), "--object", "parcel", *args, "--out", str(out),
               "--no-progress"])  # fmt: skip
    text = capsys.readouterr()
    assert rc == 0, text.err
    assert "100% of 4 directions agree" in text.out
    with (out / "gripper_xz.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert (out / "gripper_xz.png").is_file()
    got: dict[str, dict[float, tuple[float, bool]]] = {}
    for r in rows:
        got.setdefault(r["method"], {})[float(r["angle_deg"])] = (float(r["force_N"]),
                                                                   r["capped"] == "1")  # fmt: skip
    assert set(got) == {"sim", "modesearch"}
    for method in got:
        assert all(math.isfinite(v) for v, _ in got[method].values())
        for push in (0.0, 180.0):  # into a finger: held to the 10 N cap
            assert got[method][push] == (pytest.approx(10.0), True)
        up, down = got[method][90.0], got[method][270.0]  # friction, with/against the weight
        assert not up[1] and not down[1] and 3.0 < down[0] < up[0] < 10.0
    for angle in (90.0, 270.0):
        assert got["modesearch"][angle][0] == pytest.approx(got["sim"][angle][0], rel=0.15)


def _map_csv(path: Path) -> dict[float, tuple[float, bool]]:
    with path.open() as f:
        return {float(r["angle_deg"]): (float(r["force_N"]), r["capped"] == "1")
                for r in csv.DictReader(f) if r["method"] == "modesearch"}  # fmt: skip


def test_map_with_mujocos_stiffness_and_a_motion_limit(gripper: Path, tmp_path: Path,
                                                       capsys) -> None:  # fmt: skip
    """``--compliance mujoco``: the servos are springs of 5000 N/m, so a push into a finger
    moves the box by ``s / 2 kp`` (one servo pushed back, the other relieved): the 10 N cap
    within the default 2 mm (the simulated ramp's), not within 0.5 mm (at most
    ``2 kp 0.5 mm = 5 N``, less the contacts' own give)."""
    base = ["map", str(gripper), "--object", "parcel", "--plane", "xz", "--directions", "4",
            "--no-progress", "--compliance", "mujoco"]  # fmt: skip
    rc = main([*base, "--method", "sim", "modesearch", "--out", str(tmp_path / "a")])
    text = capsys.readouterr()
    assert rc == 0, text.err
    assert "100% of 4 directions agree" in text.out
    free = _map_csv(tmp_path / "a" / "gripper_xz.csv")
    assert free[0.0] == (pytest.approx(10.0), True)
    rc = main([*base, "--method", "modesearch", "--motion-limit", "0.0005", "0.05",
               "--out", str(tmp_path / "b")])  # fmt: skip
    assert rc == 0, capsys.readouterr().err
    tight = _map_csv(tmp_path / "b" / "gripper_xz.csv")
    for push in (0.0, 180.0):
        assert not tight[push][1] and 2.0 < tight[push][0] <= 5.0 + 1e-6
    for angle in (90.0, 270.0):  # friction: held with no motion, whatever the limit
        assert tight[angle][0] == pytest.approx(free[angle][0], rel=1e-6)
    assert main([*base[:-2], "--motion-limit", "0.001", "0.05"]) == 2
    _one_error_line(capsys, "needs compliance 'mujoco'")
    assert main([*base[:-2], "--near", "0.001"]) == 2
    _one_error_line(capsys, "needs compliance 'mujoco'")
    assert main([*base[:-2], "--contact-law", "fitted"]) == 2
    _one_error_line(capsys, "needs compliance 'mujoco'")
    rc = main([*base, "--method", "modesearch", "--contact-law", "fitted",
               "--out", str(tmp_path / "c")])  # fmt: skip
    assert rc == 0, capsys.readouterr().err
    law = _map_csv(tmp_path / "c" / "gripper_xz.csv")
    for push in (0.0, 180.0):  # stiffer contacts: still the cap within 2 mm
        assert law[push] == (pytest.approx(10.0), True)
    for angle in (90.0, 270.0):  # friction, held with micrometres of motion: 4e-6 apart
        assert law[angle][0] == pytest.approx(free[angle][0], rel=1e-4)


def test_sim_map_of_a_relative_path_on_workers(gripper: Path, monkeypatch) -> None:
    monkeypatch.chdir(gripper.parent)
    spec = MapSpec("gripper.xml", "xz", 2, object_body="parcel")
    one = simulated_map(spec, workers=1, progress=False)
    two = simulated_map(spec, workers=2, progress=False)
    assert np.all(np.isfinite(one.magnitudes)) and one.capped[0]  # +x: into the right finger
    np.testing.assert_array_equal(one.magnitudes, two.magnitudes)
    np.testing.assert_array_equal(one.capped, two.capped)


def test_batch_rows_of_a_file_scene(gripper: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "q.jsonl"
    rc = main(["batch", str(gripper), str(out), "--object", "parcel", "--method", "gws",
               "--directions", "2"])  # fmt: skip
    assert rc == 0, capsys.readouterr().err
    assert '"gripper-xy-0"' in out.read_text()


def test_default_commands_of_a_file(gripper: Path, tmp_path: Path) -> None:
    """Without ihm_preload: the init keyframe's controls, and the forces they hold with;
    without a keyframe: the model's default pose, and a preload closes the fingers."""
    loaded = scenes.load_scene(str(gripper), object_body="parcel")
    np.testing.assert_allclose(loaded.data.ctrl, [0.017, 0.017])
    np.testing.assert_allclose(loaded.commands, loaded.data.actuator_force)
    assert np.all(loaded.commands > 5.0)
    bare = tmp_path / "bare.xml"
    bare.write_text(GRIPPER.replace("KEYFRAME", ""))
    loaded = scenes.load_scene(str(bare), preload=[6.0, 6.0], object_body="parcel")
    np.testing.assert_allclose(loaded.commands, [6.0, 6.0])
    np.testing.assert_allclose(loaded.data.actuator_force, [6.0, 6.0], rtol=0.01)
    with pytest.raises(scenes.SceneError, match="no ihm_preload.*give a preload"):
        scenes.load_scene(str(bare), object_body="parcel")  # controls 0: the fingers stay open


def test_errors_exit_2_with_one_line(gripper: Path, tmp_path: Path, capsys) -> None:
    missing = str(tmp_path / "nope.xml")
    assert main(["show", missing, "--object", "parcel"]) == 2
    _one_error_line(capsys, "python -m ihm show: error:", "not found", "nope.xml")
    assert main(["map", missing, "--object", "parcel", "--no-progress"]) == 2
    _one_error_line(capsys, "python -m ihm map: error:", "not found")
    assert main(["map", str(gripper), "--no-progress"]) == 2  # the default body, "object"
    _one_error_line(capsys, "no free body named 'object'", "parcel")
    assert main(["show", str(gripper), "--object", "left"]) == 2  # a hand link: not free
    _one_error_line(capsys, "no free body named 'left'")
    broken = tmp_path / "broken.xml"
    broken.write_text("<mujoco><worldbody><body>")
    assert main(["map", str(broken), "--method", "modesearch", "--no-progress"]) == 2
    _one_error_line(capsys, "does not compile")
    assert main(["batch", str(gripper), str(tmp_path / "q.jsonl"), "--object", "box"]) == 2
    _one_error_line(capsys, "python -m ihm batch: error:", "no free body named 'box'")
