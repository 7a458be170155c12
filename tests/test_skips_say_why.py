"""A test skips only for a capability the machine lacks (Chromium, AVX2, `chattr +i`), and its reason says so; a missing
package of the test extras or a pinned reference that drifted fails instead (docs/development.md)."""

from __future__ import annotations

import ast
from pathlib import Path

TESTS = Path(__file__).resolve().parent
SKIPS = {"skip", "skipif", "importorskip", "xfail"}
PREFIX = "machine capability: "


def _name(func: ast.expr) -> str | None:
    return func.attr if isinstance(func, ast.Attribute) else func.id if isinstance(func, ast.Name) else None


def _reason(call: ast.Call) -> ast.expr | None:
    for k in call.keywords:
        if k.arg in ("reason", "msg"):
            return k.value
    args = call.args[1:] if _name(call.func) == "skipif" else call.args
    return args[0] if args else None


def _starts_with_prefix(expr: ast.expr | None) -> bool:
    if isinstance(expr, ast.Constant) and isinstance(expr.value, str):
        return expr.value.startswith(PREFIX)
    if isinstance(expr, ast.JoinedStr) and expr.values:
        return _starts_with_prefix(expr.values[0])
    return False


def test_every_skip_names_the_missing_machine_capability():
    bad = []
    for path in sorted(TESTS.rglob("*.py")):
        if path == Path(__file__).resolve():
            continue
        text = path.read_text()
        if "skip" not in text and "xfail" not in text:  # every name in SKIPS holds one of the two: nothing to find
            continue
        for node in ast.walk(ast.parse(text, str(path))):
            where = f"{path.relative_to(TESTS)}:{getattr(node, 'lineno', 0)}"
            if isinstance(node, (ast.FunctionDef, ast.ClassDef)):  # a bare @pytest.mark.skip has no reason at all
                bad += [f"{where}: {_name(d)} without a reason" for d in node.decorator_list if _name(d) in SKIPS]
            if not isinstance(node, ast.Call) or _name(node.func) not in SKIPS:
                continue
            name = _name(node.func)
            if name in ("importorskip", "xfail"):
                bad.append(f"{where}: {name} (a missing package fails, and so does an expected failure)")
            elif not _starts_with_prefix(_reason(node)):
                bad.append(f"{where}: {name} without a reason starting {PREFIX!r}")
    assert not bad, "skips that are not for a missing machine capability:\n" + "\n".join(bad)
