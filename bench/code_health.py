"""The code-health counts of issue #40, read from the source tree (nothing of jitroute is imported or run).

- lines and files of `pipeline/routing` (every line of its .py files);
- numba kernels: functions decorated with numba's `njit` / `jit` (`@numba.njit(...)`, `@njit`, ...), in all and with
  10 parameters or more, and how many are compiled with `cache=True`;
- functions over cyclomatic complexity 10: ruff's C901 (mccabe) with max-complexity 10, over the packages;
- cross-file calls from a `cache=True` kernel to a kernel defined in another file (numba's cache checks only the
  caller's own file, see pipeline/compile_cache.py): the callers and the call sites;
- import circles: files of the packages that import each other in a loop (strongly connected components of the
  import graph, every import statement of a file counted, also those inside functions).

Prints a table (with --list also what each count is made of; --json: all of it as JSON).

    .venv/bin/python bench/code_health.py [--list] [--json] [--root CHECKOUT]
"""

from __future__ import annotations

import argparse
import ast
import json
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("schemas", "pipeline", "storage", "flows", "cli", "deploy")
ROUTING = "pipeline/routing"
MANY_PARAMS = 10
MAX_COMPLEXITY = 10
JIT_NAMES = {"njit", "jit"}


@dataclass
class Kernel:
    module: str  # dotted, e.g. pipeline.routing.geodesy
    name: str
    n_params: int
    cached: bool
    node: ast.FunctionDef = field(repr=False)


def source_files(root: Path = ROOT, packages: tuple[str, ...] = PACKAGES) -> list[Path]:
    """The .py files of the packages (those present under `root`), caches left out, sorted."""
    return sorted(p for pkg in packages for p in (root / pkg).rglob("*.py") if "__pycache__" not in p.parts)


def module_name(path: Path, root: Path = ROOT) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _jit_decorator(dec: ast.expr) -> ast.expr | None:
    """The decorator when it is numba's njit/jit (called or bare), else None."""
    target = dec.func if isinstance(dec, ast.Call) else dec
    name = target.attr if isinstance(target, ast.Attribute) else target.id if isinstance(target, ast.Name) else None
    return dec if name in JIT_NAMES else None


def kernels_of(tree: ast.Module, module: str) -> list[Kernel]:
    out = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.FunctionDef):
            continue
        for dec in node.decorator_list:
            if _jit_decorator(dec) is None:
                continue
            cached = isinstance(dec, ast.Call) and any(
                k.arg == "cache" and isinstance(k.value, ast.Constant) and k.value.value is True for k in dec.keywords)
            a = node.args
            n = len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) + (a.vararg is not None) + (a.kwarg is not None)
            out.append(Kernel(module, node.name, n, cached, node))
            break
    return out


def _resolve(module: str, level: int, name: str | None, is_package: bool) -> str:
    """The absolute module of `from <level dots><name> import ...` written in `module`."""
    if not level:
        return name or ""
    base = module.split(".") if is_package else module.split(".")[:-1]
    base = base[:len(base) - (level - 1)]
    return ".".join(base + ([name] if name else []))


def imported_names(tree: ast.Module, module: str, is_package: bool) -> dict[str, str]:
    """Local name → what it stands for, dotted (a module, or module.attribute), from every import of the file."""
    names = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.asname:
                    names[a.asname] = a.name
                else:
                    names[a.name.split(".")[0]] = a.name.split(".")[0]
        elif isinstance(node, ast.ImportFrom):
            src = _resolve(module, node.level, node.module, is_package)
            for a in node.names:
                names[a.asname or a.name] = f"{src}.{a.name}"
    return names


def _dotted(expr: ast.expr) -> str | None:
    if isinstance(expr, ast.Name):
        return expr.id
    if isinstance(expr, ast.Attribute):
        head = _dotted(expr.value)
        return None if head is None else f"{head}.{expr.attr}"
    return None


def cross_file_calls(kernels: list[Kernel], imports: dict[str, dict[str, str]]) -> list[tuple[str, str, int]]:
    """(caller, callee, line) of each call in a cache=True kernel to a kernel of another file."""
    by_dotted = {f"{k.module}.{k.name}": k for k in kernels}
    out = []
    for k in kernels:
        if not k.cached:
            continue
        names = imports[k.module]
        for node in ast.walk(k.node):
            if not isinstance(node, ast.Call):
                continue
            dotted = _dotted(node.func)
            if dotted is None:
                continue
            head, _, rest = dotted.partition(".")
            if head not in names:
                continue
            target = names[head] + (f".{rest}" if rest else "")
            callee = by_dotted.get(target)
            if callee is not None and callee.module != k.module:
                out.append((f"{k.module}.{k.name}", target, node.lineno))
    return out


def _top_level(tree: ast.Module):
    """The statements run when the module is imported: its body, into if/try/with blocks, not into functions or classes
    nor under `if TYPE_CHECKING:`."""
    todo = list(tree.body)
    while todo:
        node = todo.pop()
        yield node
        if isinstance(node, ast.If) and _dotted(node.test) in ("TYPE_CHECKING", "typing.TYPE_CHECKING"):
            todo.extend(node.orelse)
        elif not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            todo.extend(n for n in ast.iter_child_nodes(node) if isinstance(n, ast.stmt))


def import_graph(trees: dict[str, tuple[ast.Module, bool]], top_level_only: bool = False) -> dict[str, set[str]]:
    """Module → the modules of the packages it imports (a name imported from a package is its submodule when there
    is one, else the package itself); every import of the file, or only those run at import time."""
    known = set(trees)
    graph: dict[str, set[str]] = {m: set() for m in trees}
    for module, (tree, is_package) in trees.items():
        for node in (_top_level(tree) if top_level_only else ast.walk(tree)):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                src = _resolve(module, node.level, node.module, is_package)
                targets = [f"{src}.{a.name}" if f"{src}.{a.name}" in known else src for a in node.names]
            for t in targets:
                while t and t not in known:  # `import a.b.c` of a name inside c: its module
                    t = t.rpartition(".")[0]
                if t and t != module:
                    graph[module].add(t)
    return graph


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan), each sorted, largest first."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10 * len(graph) + 100))
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(out, key=lambda c: (-len(c), c))


def complex_functions(root: Path = ROOT, packages: tuple[str, ...] = PACKAGES) -> list[str]:
    """`file:line: message` of each function over MAX_COMPLEXITY (ruff's C901), or [] with a note when ruff is missing."""
    cmd = [sys.executable, "-m", "ruff", "check", "--isolated", "--select", "C901", "--output-format", "json",
           "--config", f"lint.mccabe.max-complexity = {MAX_COMPLEXITY}", *packages]
    try:
        r = subprocess.run(cmd, cwd=root, capture_output=True, text=True, timeout=300)
        found = json.loads(r.stdout or "[]")
    except (OSError, ValueError, subprocess.TimeoutExpired) as exc:
        raise SystemExit(f"ruff could not count the complexity ({exc}); install the test extras (ruff)") from None
    return sorted(f"{Path(f['filename']).relative_to(root)}:{f['location']['row']}: {f['message']}" for f in found)


def measure(root: Path = ROOT) -> dict:
    """Every count, with what it is made of (lists), for the packages under `root`."""
    files = source_files(root)
    trees = {module_name(p, root): (ast.parse(p.read_text(), str(p)), p.name == "__init__.py") for p in files}
    kernels = [k for m, (t, _) in trees.items() for k in kernels_of(t, m)]
    imports = {m: imported_names(t, m, is_pkg) for m, (t, is_pkg) in trees.items()}
    calls = cross_file_calls(kernels, imports)
    routing = [p for p in files if p.is_relative_to(root / ROUTING)]
    complex_ = complex_functions(root, tuple(p for p in PACKAGES if (root / p).is_dir()))
    loops = circles(import_graph(trees))
    loops_at_import = circles(import_graph(trees, top_level_only=True))
    return {
        "routing_lines": sum(len(p.read_text().splitlines()) for p in routing),
        "routing_files": len(routing),
        "routing_kernels": sum(k.module.startswith(ROUTING.replace("/", ".")) for k in kernels),
        "kernels": len(kernels),
        "kernels_cached": sum(k.cached for k in kernels),
        "kernels_many_params": sorted(f"{k.module}.{k.name} ({k.n_params})" for k in kernels if k.n_params >= MANY_PARAMS),
        "complex_functions": complex_,
        "complex_in_routing": [c for c in complex_ if c.startswith(ROUTING + "/")],
        "cross_file_calls": [f"{a} -> {b} (line {n})" for a, b, n in calls],
        "cross_file_callers": sorted({a for a, _, _ in calls}),
        "circles": loops,
        "circles_at_import": loops_at_import,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--list", action="store_true", help="also list what each count is made of")
    ap.add_argument("--json", action="store_true", help="print every count and list as one JSON object instead")
    ap.add_argument("--root", type=Path, default=ROOT, help="the checkout to measure (default: this one)")
    args = ap.parse_args()
    m = measure(args.root.resolve())
    if args.json:
        print(json.dumps(m, indent=1))
        return
    rows = [
        (f"lines in {ROUTING} ({m['routing_files']} files)", m["routing_lines"]),
        ("numba kernels (njit/jit)", f"{m['kernels']} ({m['kernels_cached']} cache=True; {m['routing_kernels']} in routing)"),
        (f"kernels with >= {MANY_PARAMS} parameters", len(m["kernels_many_params"])),
        (f"functions over complexity {MAX_COMPLEXITY} (C901)", f"{len(m['complex_functions'])} "
                                                              f"({len(m['complex_in_routing'])} in routing)"),
        ("cache=True kernels calling a kernel of another file", len(m["cross_file_callers"])),
        ("  their call sites", len(m["cross_file_calls"])),
        ("import circles (files in them)", f"{len(m['circles'])} ({sum(len(c) for c in m['circles'])})"),
        ("  of imports run at import time", f"{len(m['circles_at_import'])} "
                                            f"({sum(len(c) for c in m['circles_at_import'])})"),
    ]
    width = max(len(r[0]) for r in rows)
    print(f"code health of {', '.join(PACKAGES)}")
    for what, value in rows:
        print(f"  {what:<{width}}  {value}")
    for c in m["circles"]:
        print(f"  circle{' (at import)' if c in m['circles_at_import'] else ''}: {' <-> '.join(c)}")
    if args.list:
        for key in ("kernels_many_params", "complex_functions", "cross_file_calls"):
            print(f"\n{key}:")
            for line in m[key]:
                print(f"  {line}")


if __name__ == "__main__":
    main()
