"""``python -m train.rollout`` and the rerun recorder it shares with ``ihm show --rrd``.

Recordings are read back with rerun's own reader (``rerun.chunk.RrdReader``): entity
paths, the ``step``/``sim_time`` timelines, poses equal to MuJoCo's, contact forces that
carry the object's weight, the shield's executed actions; and bad options exit 2 with a
message naming the option."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rerun.chunk import RrdReader

from envs.four_finger import FourFingerRotate
from ihm.hands.four_finger import ACTUATOR_NAMES
from ihm.rerun_log import SceneRecorder, object_contacts
from train import rollout

DT = 0.05  # policy step of FourFingerRotate [s]


def read_rrd(path: str | Path) -> dict[str, list[dict[str, list[Any]]]]:
    """Entity path -> its chunks (column name -> values), from the file's recording."""
    chunks: dict[str, list[dict[str, list[Any]]]] = defaultdict(list)
    for chunk in RrdReader(path).stream():
        batch = chunk.to_record_batch()
        chunks[batch.schema.metadata[b"rerun:entity_path"].decode()].append(batch.to_pydict())
    return chunks


def series(chunks: dict, entity: str, component: str) -> dict[int | None, Any]:
    """Step -> value of one component (None -> its static value)."""
    out: dict[int | None, Any] = {}
    for c in chunks[entity]:
        if component not in c:
            continue
        steps = c.get("step", [None] * len(c[component]))
        out.update(zip(steps, c[component], strict=True))
    return out


def scalar(chunks: dict, entity: str) -> dict[int | None, float]:
    return {k: v[0] for k, v in series(chunks, entity, "Scalars:scalars").items()}


def test_rollout_writes_rrd(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    n = 6
    (res,) = rollout.main(["--shield", "none", "--steps", str(n), "--out", str(tmp_path)])
    path = Path(res["path"])
    assert path.parent == tmp_path and path.suffix == ".rrd"
    assert f"{path}: shield none, {n} steps" in capsys.readouterr().out
    assert res["steps"] == n and not res["dropped"] and res["interventions"] == 0
    reader = RrdReader(path)
    assert len(reader.recordings()) == 1 and len(reader.blueprints()) == 1
    chunks = read_rrd(path)
    names = [f"/actions/{who}/{a}" for who in ("agent", "executed") for a in ACTUATOR_NAMES]
    for entity in (
        "/world/geoms/object/object",
        "/world/geoms/f1_distal/f1_distal_visual",
        "/world/contacts/points",
        "/world/contacts/forces",
        "/world/object",
        "/reward",
        "/rotation_angle",
        "/shield/intervened",
        "/shield/correction",
        *names,
    ):
        assert entity in chunks, entity
    assert "/world/geoms/f1_distal/f1_distal" not in chunks  # collision capsules left out
    # the scene at steps 0..n (0: the start grasp), what led to it at 1..n
    pose = series(chunks, "/world/geoms/object/object", "Transform3D:translation")
    assert sorted(pose) == list(range(n + 1))
    assert sorted(series(chunks, "/world/contacts/points", "Points3D:positions")) == list(
        range(n + 1)
    )
    for entity in names + ["/reward", "/shield/intervened"]:
        assert sorted(scalar(chunks, entity)) == list(range(1, n + 1)), entity
    (c,) = [c for c in chunks["/reward"] if "sim_time" in c]
    assert [t.total_seconds() for t in c["sim_time"]] == pytest.approx(DT * np.arange(1, n + 1))
    # no shield: executed = agent, no interventions; the summary is the logged angle / time
    for a in ACTUATOR_NAMES:
        assert scalar(chunks, f"/actions/executed/{a}") == scalar(chunks, f"/actions/agent/{a}")
    assert set(scalar(chunks, "/shield/intervened").values()) == {0.0}
    angle = scalar(chunks, "/rotation_angle")
    assert angle[0] == 0.0
    assert res["speed_rad_s"] == pytest.approx(angle[n] / (n * DT), rel=1e-5)
    assert abs(res["speed_rad_s"]) > 0.05  # the policy turns the sphere from the first steps


def test_recorder_poses_and_contacts_match_mujoco(tmp_path: Path) -> None:
    env = FourFingerRotate()
    env.reset(seed=1)
    m, d = env.model, env.data
    rng = np.random.default_rng(0)
    xpos, xmat, contacts = [], [], []
    scale = 0.02
    with SceneRecorder(m, tmp_path / "r.rrd", groups=(0, 1, 2)) as rec:
        for k in range(4):
            rec.set_time(k, k * env.dt)
            rec.log_poses(d)
            contacts.append(rec.log_object(d, force_scale=scale))
            xpos.append(d.geom_xpos.copy())
            xmat.append(d.geom_xmat.copy())
            env.step(rng.uniform(-1, 1, 12).astype(np.float32))
        entities = dict(rec.entities)
    env.close()
    chunks = read_rrd(tmp_path / "r.rrd")
    k = 2
    assert not np.allclose(xpos[k], xpos[0], atol=1e-5)  # the chosen step is not the start
    for g, entity in entities.items():
        t = series(chunks, "/" + entity, "Transform3D:translation")
        r = series(chunks, "/" + entity, "Transform3D:mat3x3")
        key = None if None in t else k  # the palm is welded to the world: one static pose
        if m.body(int(m.geom_bodyid[g])).name in ("object", "f1_distal"):
            assert key == k, entity
        np.testing.assert_allclose(t[key][0], xpos[k][g], atol=1e-6)  # float32 in rerun
        # rerun stores matrices column-major
        np.testing.assert_allclose(
            np.reshape(r[key][0], (3, 3)).T, xmat[k][g].reshape(3, 3), atol=1e-6
        )
    # contact arrows: force on the object [N] x scale; at the settled start grasp they carry
    # the sphere's weight (0.1 kg x 9.81 m/s^2, +z): the sign and the magnitude
    arrows = series(chunks, "/world/contacts/forces", "Arrows3D:vectors")
    points = series(chunks, "/world/contacts/points", "Points3D:positions")
    for step, c in enumerate(contacts):
        assert len(arrows[step]) == len(points[step]) == len(c) > 0
        np.testing.assert_allclose(arrows[step], scale * c.forces, atol=1e-6)
    np.testing.assert_allclose(np.sum(arrows[0], axis=0) / scale, [0, 0, 0.981], atol=0.03)
    labels = series(chunks, "/world/contacts/points", "Points3D:labels")
    assert set(labels[0]) <= {
        f"f{i}_{link}" for i in range(1, 5) for link in ("proximal", "distal")
    }


def test_object_contacts_bad_body() -> None:
    env = FourFingerRotate()
    env.reset(seed=0)
    with pytest.raises(ValueError, match="no body 'nope'"):
        object_contacts(env.model, env.data, "nope")
    env.close()


def test_rollout_both_shield_settings(tmp_path: Path) -> None:
    """``--shield both``: the bare and the shielded run start from the same grasp with the
    same agent actions; the executed action is the agent's wherever the shield did not
    intervene, and the logged interventions match the printed count."""
    n = 6
    argv = [
        "--random",
        "--shield",
        "both",
        "--steps",
        str(n),
        "--seed",
        "7",
        "--out",
        str(tmp_path),
    ]
    plain, shielded = rollout.main(argv)
    assert (plain["shield"], shielded["shield"]) == ("none", "qp")
    a, b = read_rrd(plain["path"]), read_rrd(shielded["path"])
    pose = "/world/geoms/object/object"
    assert (
        series(a, pose, "Transform3D:translation")[0]
        == series(b, pose, "Transform3D:translation")[0]
    )
    intervened = scalar(b, "/shield/intervened")
    changed = dict.fromkeys(intervened, False)
    for name in ACTUATOR_NAMES:
        agent = scalar(b, f"/actions/agent/{name}")
        assert agent == scalar(a, f"/actions/agent/{name}")
        executed = scalar(b, f"/actions/executed/{name}")
        for step, x in agent.items():
            assert -1.0 <= executed[step] <= 1.0
            if not intervened[step]:
                assert executed[step] == pytest.approx(x, abs=1e-6)
            changed[step] |= abs(executed[step] - x) > 1e-9
    assert all(changed[s] for s, v in intervened.items() if v)
    assert sum(intervened.values()) == shielded["interventions"]
    st = shielded["statuses"]
    assert st.get("corrected", 0) + st.get("fallback", 0) == shielded["interventions"]
    assert sum(st.values()) == len(intervened)
    assert plain["interventions"] == 0 and set(scalar(a, "/shield/intervened").values()) == {0.0}


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--episodes", "0"], "--episodes must be >= 1"),
        (["--steps", "0"], "--steps must be >= 1"),
        (["--policy", "/no/such/policy"], "--policy /no/such/policy: no such directory"),
        (["--random", "--policy", "x"], "--random and --policy exclude each other"),
        (["--force-scale", "nan"], "--force-scale must be a finite number"),
        (["--shield", "sometimes"], "invalid choice: 'sometimes'"),
    ],
)
def test_bad_options_exit_2(argv: list[str], message: str, capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit) as exc:
        rollout.main(["--shield", "none", *argv])
    assert exc.value.code == 2
    assert message in capsys.readouterr().err


def test_not_a_policy_dir(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    (tmp_path / "config.json").write_text("{}")
    with pytest.raises(SystemExit):
        rollout.main(["--shield", "none", "--policy", str(tmp_path)])
    err = capsys.readouterr().err
    assert "not a policy directory (missing policy.pt or model.zip, vecnormalize.pkl)" in err
    assert not list(tmp_path.glob("*.rrd"))
