"""The README's Python quick start runs, and every value its comments claim is what it gets.

The convention, stated in the README itself: a line ``expr  # -> value`` claims that the
expression evaluates to ``value``, a Python literal, optionally followed by two spaces and
a note. A number holds to the digits shown (``2.2223`` means within 0.00005, an integer
exactly); lists, tuples and dicts compare item by item; numpy arrays and scalars compare
as their Python values. Lines without ``# ->`` are just run. The blocks are the ```python
fences of the "Quick start" section, each run in a fresh namespace.
"""

from __future__ import annotations

import ast
import math
import os
import re
import subprocess
import sys
from decimal import Decimal
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
CLAIM = re.compile(r"#\s*->\s*(.+?)\s*$")


def quickstart_blocks(readme: str) -> list[str]:
    """The ```python fences between "## Quick start" and the next "## " heading."""
    section = readme.split("\n## Quick start", 1)[1].split("\n## ", 1)[0]
    return re.findall(r"```python\n(.*?)```", section, re.S)


def claimed(line: str) -> str | None:
    """The literal a line claims (``# -> value``, a note after two spaces), else None."""
    m = CLAIM.search(line)
    if m is None:
        return None
    text = m.group(1).split("  ", 1)[0]
    ast.literal_eval(text)  # a Python literal, or this raises
    return text


def _tolerance(node: ast.Constant, source: str) -> float:
    digits = ast.get_source_segment(source, node) or repr(node.value)
    return 0.5 * 10.0 ** Decimal(digits).as_tuple().exponent


def matches(actual: object, node: ast.expr, source: str) -> bool:
    """Whether ``actual`` is the literal ``node`` (parsed from ``source``) to its digits."""
    if hasattr(actual, "tolist"):  # numpy arrays and scalars
        actual = actual.tolist()
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
        inner = node.operand
        return isinstance(actual, (int, float)) and matches(-actual, inner, source)
    if isinstance(node, (ast.List, ast.Tuple)):
        return (
            isinstance(actual, (list, tuple))
            and type(actual) is (list if isinstance(node, ast.List) else tuple)
            and len(actual) == len(node.elts)
            and all(matches(a, n, source) for a, n in zip(actual, node.elts, strict=True))
        )
    if isinstance(node, ast.Dict):
        keys = [ast.literal_eval(k) for k in node.keys]
        return (
            isinstance(actual, dict)
            and sorted(actual, key=repr) == sorted(keys, key=repr)
            and all(matches(actual[k], v, source) for k, v in zip(keys, node.values, strict=True))
        )
    assert isinstance(node, ast.Constant), ast.dump(node)
    want = node.value
    if isinstance(want, bool) or want is None or isinstance(want, str):
        return type(actual) is type(want) and actual == want
    if isinstance(actual, bool) or not isinstance(actual, (int, float)):
        return False
    if isinstance(want, int):
        return actual == want
    return math.isfinite(actual) and abs(actual - want) <= _tolerance(node, source) * (1 + 1e-9)


def run_block(code: str) -> tuple[int, list[str]]:
    """Run one block statement by statement; check every claim. Returns (claims, failures)."""
    tree = ast.parse(code)
    lines = code.splitlines()
    namespace: dict[str, object] = {"__name__": "__readme__"}
    n, failures = 0, []
    for stmt in tree.body:
        line = lines[stmt.end_lineno - 1]
        claim = claimed(line)
        if claim is None:
            exec(compile(ast.Module([stmt], []), "README.md", "exec"), namespace)
            continue
        assert isinstance(stmt, ast.Expr), f"a claim on a statement, not an expression: {line}"
        n += 1
        value = eval(compile(ast.Expression(stmt.value), "README.md", "eval"), namespace)
        if not matches(value, ast.parse(claim, mode="eval").body, claim):
            failures.append(f"{line.strip()}\n    got {value!r}")
    return n, failures


BLOCKS = quickstart_blocks((ROOT / "README.md").read_text(encoding="utf-8"))


def test_quickstart_found() -> None:
    assert len(BLOCKS) >= 2, "the README's quick start has a solver and an env block"


@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_quickstart_runs_and_claims_hold(index: int, capfd: pytest.CaptureFixture[str]) -> None:
    n, failures = run_block(BLOCKS[index])
    out, _ = capfd.readouterr()
    assert n >= 3, f"block {index} claims too little ({n} values)"
    assert not failures, "README quick start drifted from the code:\n" + "\n".join(failures)
    for banner in ("Running HiGHS", "Copyright"):
        assert banner not in out, f"a solver banner reached stdout: {out[:300]!r}"


def test_quickstart_prints_no_solver_banner() -> None:
    """In a fresh process: HiGHS prints its banner once per process, so an earlier test in
    this session could hide it from the in-process check above."""
    code = "\n".join(f"exec(compile({b!r}, 'README.md', 'exec'), {{}})" for b in BLOCKS)
    path = os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])
    env = {**os.environ, "PYTHONPATH": path}
    run = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, timeout=600
    )
    assert run.returncode == 0, run.stderr[-2000:]
    for banner in ("Running HiGHS", "Copyright"):
        assert banner not in run.stdout, f"a solver banner reached stdout: {run.stdout[:300]!r}"


@pytest.mark.parametrize(
    ("actual", "literal", "ok"),
    [
        (2.222264, "2.2223", True),
        (2.2224, "2.2223", False),
        (np.float64(0.0899983), "0.09", True),
        (np.array([[1.0, -0.5]]), "[[1.0, -0.5]]", True),
        (np.array(["roll", "slip-"]), "['roll', 'slip-']", True),
        (np.bool_(True), "True", True),
        (1, "True", False),
        (True, "1", False),
        ((56,), "(56,)", True),
        ([56], "(56,)", False),
        (56.4, "56", False),
        (-1.5, "-1.5", True),
        ({"a": 1.04}, "{'a': 1.0}", True),
        ([1.0, 2.0], "[1.0]", False),
        (float("nan"), "1.0", False),
    ],
)
def test_claim_rule(actual: object, literal: str, ok: bool) -> None:
    """The comparison the README's claims go through (a number holds to its digits)."""
    assert matches(actual, ast.parse(literal, mode="eval").body, literal) is ok


def test_claim_parsing() -> None:
    assert claimed("x  # -> 1.0  a note") == "1.0"
    assert claimed("x  # -> ['a', 'b']") == "['a', 'b']"
    assert claimed("x  # just prose") is None
    with pytest.raises(ValueError):
        claimed("x  # -> not_a_literal")
