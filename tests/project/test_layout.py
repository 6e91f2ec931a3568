"""The shape of the house (docs/design.md, Packages and the import rule; Files and tests):
one-way layers, no circles, rooms of readable size, no private name crossing a module
boundary.

The layers ``stability <- ihm <- envs <- shields <- train`` and the absence of import circles
are import-linter contracts in ``pyproject.toml`` (``lint-imports`` checks them, lazy imports
inside functions included); these tests run it on the tree and on a copy with a planted
back-import, to show that a violation fails with a message naming the import.
"""

from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("stability", "ihm", "envs", "shields", "train")
MAX_LINES = 650  # docs/design.md, Files and tests: about 650 lines per module at most
# a module may exceed MAX_LINES only if its docstring says why, with this phrase
EXCEPTION_PHRASE = "over 650 lines"

LINT = "import sys; from importlinter.cli import lint_imports as f; sys.exit(f(no_cache=True))"


def _lint(cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", LINT], cwd=cwd, capture_output=True, text=True, timeout=300
    )


def _sources() -> list[Path]:
    return sorted(p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py"))


def test_import_contracts_hold() -> None:
    res = _lint(ROOT)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "3 kept, 0 broken" in res.stdout


def test_a_planted_back_import_fails_naming_the_import(tmp_path: Path) -> None:
    for name in (*PACKAGES, "pyproject.toml"):
        src = ROOT / name
        if src.is_dir():
            shutil.copytree(src, tmp_path / name, ignore=shutil.ignore_patterns("__pycache__"))
        else:
            shutil.copy(src, tmp_path / name)
    # a lazy import inside a function: the kind that used to slip through
    (tmp_path / "envs" / "planted.py").write_text(
        "def f():\n    from train import ppo\n\n    return ppo\n"
    )
    res = _lint(tmp_path)
    assert res.returncode != 0
    assert "envs is not allowed to import train" in res.stdout
    assert "envs.planted -> train.ppo (l.2)" in res.stdout
    # and a circle between two sibling modules
    (tmp_path / "envs" / "planted.py").unlink()
    (tmp_path / "stability" / "planted_a.py").write_text("from stability import planted_b\n")
    (tmp_path / "stability" / "planted_b.py").write_text("from stability import planted_a\n")
    res = _lint(tmp_path)
    assert res.returncode != 0
    assert "No cycles are allowed in stability" in res.stdout


@pytest.mark.parametrize("path", _sources(), ids=lambda p: str(p.relative_to(ROOT)))
def test_module_size(path: Path) -> None:
    text = path.read_text()
    n = text.count("\n")
    if n > MAX_LINES:
        doc = ast.get_docstring(ast.parse(text)) or ""
        assert EXCEPTION_PHRASE in doc, f"{n} lines and no stated exception in the docstring"


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def private_crossings(source: str, me: str, is_package: bool = False) -> list[str]:
    """Private names of another module used in the module ``me`` (its ``source``):
    ``from m import _x`` and ``m._x`` where ``m`` is a module of the project imported there
    (``self._x`` and the module's own names are its own business)."""
    tree = ast.parse(source)
    package = me if is_package else me.rpartition(".")[0]
    modules: dict[str, str] = {}  # local name -> project module
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*anchor, *([base] if base else [])])
            if base.split(".")[0] not in PACKAGES:
                continue
            for a in node.names:
                if _private(a.name) and base != me:
                    found.append(f"l.{node.lineno}: from {base} import {a.name}")
                modules[a.asname or a.name] = f"{base}.{a.name}"
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] in PACKAGES:
                    modules[a.asname or a.name.split(".")[0]] = a.asname and a.name or a.name
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Attribute)
            and _private(node.attr)
            and isinstance(node.value, ast.Name)
            and node.value.id in modules
        ):
            found.append(f"l.{node.lineno}: {node.value.id}.{node.attr}")
    return found


@pytest.mark.parametrize("path", _sources(), ids=lambda p: str(p.relative_to(ROOT)))
def test_no_private_name_crosses_modules(path: Path) -> None:
    found = private_crossings(path.read_text(), _module_name(path), path.name == "__init__.py")
    assert found == []


def test_the_private_name_check_catches_both_forms() -> None:
    src = "from ihm.render import _x\nfrom ..four_finger import _y\nfrom . import geometry\n"
    src += "geometry._z\nfrom .bench import _own\nself._fine\n"
    found = private_crossings(src, "envs.four_finger.env")
    assert found == [
        "l.1: from ihm.render import _x",
        "l.2: from envs.four_finger import _y",
        "l.5: from envs.four_finger.bench import _own",
        "l.4: geometry._z",
    ]
    assert private_crossings("from .a import _b\n", "envs.a") == []  # its own name


def test_importing_the_packages_has_no_side_effects() -> None:
    """``import stability, ihm, envs, shields, train`` in a fresh interpreter leaves the
    environment variables as they were and prints nothing (measured after the third-party
    packages they use are imported: gymnasium sets one of its own)."""
    code = (
        "import os, json, mujoco, gymnasium, stable_baselines3, torch, highspy, pyscipopt; "
        "before = dict(os.environ); "
        "import stability, ihm, envs, shields, train; "
        "print(json.dumps(sorted(set(os.environ.items()) ^ set(before.items()))))"
    )
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM")}
    p = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True,
                       text=True, timeout=300)  # fmt: skip
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip() == "[]" and p.stderr == "", (p.stdout, p.stderr)
