"""Smoke tests of every command-line entry point of ``train`` (and of the moved benchmarks'
old homes ``envs.bench`` and ``shields.bench``): ``--help`` of each, one-line errors with
exit status 2, tiny runs of the benchmarks that moved under ``train.bench``.

(Tiny training runs: tests/train/test_islands_training.py and test_rotation_train_smoke.py;
rollouts: test_rollout.py; the shield benchmarks' numbers: test_shield_bench.py.)"""

from __future__ import annotations

import csv
import os
import runpy
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def run(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    """``python -m *args`` in a subprocess from the checkout."""
    env = {**os.environ, "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg"}
    return subprocess.run(
        [sys.executable, "-m", *args],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=timeout,
    )  # fmt: skip


def run_here(capsys: pytest.CaptureFixture[str], *args: str) -> subprocess.CompletedProcess:
    """``python -m *args`` in this process (as ``runpy`` runs it for ``-m``): the exit
    status and what it printed, without a new interpreter's imports per command."""
    module, *argv = args
    saved = sys.argv
    sys.argv = [module, *argv]
    code: int | str | None = 0
    try:
        with warnings.catch_warnings():  # the module is imported already: runpy says so
            warnings.simplefilter("ignore", RuntimeWarning)
            runpy.run_module(module, run_name="__main__", alter_sys=True)
    except SystemExit as e:
        code = e.code
    finally:
        sys.argv = saved
    out = capsys.readouterr()
    rc = code if isinstance(code, int) else (0 if code is None else 1)
    return subprocess.CompletedProcess(list(args), rc, out.out, out.err)


HELP = [
    ("train.ppo", "--total-steps"),  # rotation (the main job)
    ("train.ppo islands", "--reward"),
    ("train.islands", "--study-nets"),
    ("train.rollout", "--force-scale"),
    ("train.gait", "--frames"),
    ("train.compare", "--window"),
    ("train.bench", "training"),
    ("train.bench training", "--rollouts"),
    ("train.bench fidelity", "--every"),
    ("train.bench transfer", "--seconds"),
    ("train.bench shield", "accuracy"),
    ("train.bench shield accuracy", "--deltas"),
    ("train.bench shield latency", "--repeats"),
    ("train.bench shield effect", "--relax-contacts"),
    ("envs.bench", "--repeats"),
]


@pytest.mark.parametrize(("command", "option"), HELP, ids=[c for c, _ in HELP])
def test_help(command: str, option: str, capsys: pytest.CaptureFixture[str]) -> None:
    p = run_here(capsys, *command.split(), "--help")
    assert p.returncode == 0, p.stderr
    assert p.stdout.startswith(f"usage: python -m {command}") and option in p.stdout


def test_rotation_help_is_the_default_and_islands_the_subcommand() -> None:
    """In new interpreters, as a user types them (the other commands run in-process)."""
    rotation, islands = run("train.ppo", "--help"), run("train.ppo", "islands", "--help")
    assert "--object" in rotation.stdout and "--object" not in islands.stdout
    assert "--env-id" in islands.stdout and "--env-id" not in rotation.stdout


@pytest.mark.parametrize(
    ("command", "message"),
    [
        ("train.ppo --shield magic", "argument --shield: invalid choice: 'magic'"),
        ("train.ppo islands --total-steps 0", "--total-steps must be >= 1"),
        ("train.islands --workers 0", "--workers must be >= 1"),
        ("train.rollout --steps x", "argument --steps: invalid int value: 'x'"),
        ("train.gait --frames", "argument --frames: expected one argument"),
        ("train.bench nope", "invalid choice: 'nope'"),
        ("train.bench shield effect --agents robot", "choose from random, policy"),
        ("train.bench shield accuracy --deltas 0", "--deltas must be finite numbers > 0"),
        ("envs.bench --steps", "argument --steps: expected one argument"),
    ],
)
def test_errors_are_one_line_and_exit_2(
    command: str, message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """A bad option prints ``prog: error: message`` and a ``--help`` hint, not the usage."""
    p = run_here(capsys, *command.split())
    assert p.returncode == 2
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 2 and message in lines[0], p.stderr
    assert lines[0].startswith("python -m ") and ": error: " in lines[0]
    assert lines[1].startswith("try 'python -m ") and lines[1].endswith(" --help'")
    assert "usage:" not in p.stderr


def test_shields_bench_prints_the_new_command_without_importing_train() -> None:
    p = run("shields.bench", "accuracy", "--states", "2")
    assert p.returncode == 2
    assert "python -m train.bench shield accuracy --states 2" in p.stderr
    code = "import sys, shields.bench; print(any(m.startswith('train') for m in sys.modules))"
    q = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )  # fmt: skip
    assert q.stdout.strip() == "False", q.stderr


def test_envs_bench_names_the_moved_parts(capsys: pytest.CaptureFixture[str]) -> None:
    for option, command in (
        ("--train", "python -m train.bench training"),
        ("--fidelity", "python -m train.bench fidelity"),
        ("--transfer", "python -m train.bench transfer"),
        ("--no-env", "python -m train.bench training|fidelity|transfer"),  # nothing left to run
    ):
        p = run_here(capsys, "envs.bench", option)
        assert p.returncode == 2 and command in p.stderr, p.stderr


def read_csv(path: Path) -> list[dict[str, str]]:
    with path.open() as f:
        return list(csv.DictReader(f))


def test_fidelity_and_transfer_tiny_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    p = run_here(
        capsys,
        "train.bench",
        "fidelity",
        "--episodes",
        "1",
        "--every",
        "32",
        "--out",
        str(tmp_path),
    )
    assert p.returncode == 0, p.stderr
    rows = read_csv(tmp_path / "four_finger_fidelity.csv")
    assert len(rows) == 7 and rows[3]["setting"] == "2 ms x 25, PGS 1e-4 (shipped)"
    assert all(int(r["states"]) == 2 for r in rows)  # steps 0 and 32 of a 64-step episode
    p = run_here(
        capsys,
        "train.bench",
        "transfer",
        "--episodes",
        "1",
        "--seconds",
        "0.5",
        "--out",
        str(tmp_path),
    )
    assert p.returncode == 0, p.stderr
    rows = read_csv(tmp_path / "four_finger_transfer.csv")
    assert [r["physics"] for r in rows[:3]] == ["1 ms x 50", "2 ms x 25", "2.5 ms x 20"]
    assert len(rows) == 6 and all(float(r["speed_rad_s"]) > 0 for r in rows)
