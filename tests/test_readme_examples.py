"""The manual's examples run as written on demo data: README.md's and every docs/*.md page's analyst SQL, Python
snippets and `route` lines; every `jitroute` command line they show names a real command and real options."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import duckdb
import pytest

ROOT = Path(__file__).resolve().parents[1]
# the manual's two layers: README.md, then every page of docs/ (pages added later are checked the same way)
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
README = "\n".join(page.read_text() for page in PAGES)


def _blocks(lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", README, flags=re.S)


def _statements(sql: str) -> list[str]:
    text = "\n".join(line for line in sql.splitlines() if not line.strip().startswith("--"))
    return [s.strip() for s in text.split(";") if s.strip()]


@pytest.fixture(scope="module")
def routed(tmp_path_factory, demo_mirror):
    """Demo data: the 2020-12-01T00 cycle, a 12-vessel demo fleet (two ships at sea) refitted and routed (gc, fast)."""
    from cli.fleet import DEMO_AT_SEA, _import_fleet
    from tests.conftest import mirror_urls, route_demo_cycle
    from flows.jobs.ingest import ingest_cycle
    from flows.jobs.refit import refit_job
    from pipeline.synthetic.fleet import generate_fleet, write_fleet

    base = tmp_path_factory.mktemp("readme")
    root = base / "data"
    assert ingest_cycle("2020-12-01T00", data_root=str(root), **mirror_urls(demo_mirror))["complete"]
    write_fleet(generate_fleet("2020-12-01T00", n_vessels=12, days=120, seed=7, at_sea=DEMO_AT_SEA), base / "fleet")
    _import_fleet(base / "fleet", root)
    refit_job(data_root=str(root))
    route_demo_cycle(root)
    return root


def test_every_analyst_query_of_the_readme_runs_and_the_numbered_ones_answer(routed):
    statements = [s for block in _blocks("sql") for s in _statements(block)]
    assert len(statements) >= 9
    con = duckdb.connect(str(routed / "warehouse.duckdb"), read_only=True)
    try:
        results = {s: con.execute(s).fetchall() for s in statements}
    finally:
        con.close()
    numbered = re.findall(r"-- (\d+)\. ", "\n".join(_blocks("sql")))
    intro = re.search(r"(\w+) questions for analysts", README)
    words = {3: "Three", 4: "Four", 5: "Five", 6: "Six", 7: "Seven", 8: "Eight"}
    assert intro and intro.group(1) == words[len(numbered)], "the manual's count of questions matches its list"
    empty = [s.split("\n")[0] for s, rows in results.items() if not rows]
    # bunker logs, rejected models, flags and fleet plans are not part of this routed root (the demo plans contracts;
    # tests/test_planning.py queries the plan tables)
    allowed = [s for s in empty if "bunker_logs" in s or "status = 'rejected'" in s or "flag IS NOT NULL" in s
               or "contract_code" in s or "FROM fleet_plans" in s]
    assert empty == allowed, f"queries answering nothing on demo data: {empty}"


def test_the_readme_python_snippets_run_on_the_demo_data(routed, monkeypatch):
    import subprocess
    import sys

    monkeypatch.chdir(routed.parent)
    for block in _blocks("python"):
        code = "\n".join(line for line in block.splitlines() if "import polars" not in line and "pl." not in line)
        code = code.replace("import pyarrow.dataset as ds, polars as pl, duckdb", "import pyarrow.dataset as ds, duckdb")
        exec(compile(code, "the manual", "exec"), {})
    for block in _blocks("sh"):
        for line in block.splitlines():
            if line.startswith(".venv/bin/python -c"):
                r = subprocess.run([sys.executable, *shlex.split(line)[1:]], capture_output=True, text=True, timeout=60)
                assert r.returncode == 0, r.stderr


def test_the_readme_route_example_runs_as_written(routed):
    from tests.processes import jitroute, new_tag, tagged_env

    lines = [ln for block in _blocks("sh") for ln in block.replace("\\\n", " ").splitlines()
             if ln.startswith("jitroute route --from")]
    assert len(lines) >= 1
    for line in lines:
        args = shlex.split(re.sub(r"\[[^\]]*\]", "", line.split("#")[0]))[1:]
        r = jitroute(*args, "--solver", "gc", "--data", str(routed), env=tagged_env(new_tag()), timeout_s=600)
        assert r.returncode == 0, line + "\n" + r.stdout[-2000:] + r.stderr[-2000:]
        assert "status ok" in r.stdout or "status late" in r.stdout


def _command_lines() -> list[tuple[str, str]]:
    """Every `jitroute …` command shown in a sh block of the manual, as (page, command) with its continuation lines
    (a trailing backslash, or an indented line under it) joined and comments dropped."""
    found = []
    for page in PAGES:
        for block in re.findall(r"```sh\n(.*?)```", page.read_text(), flags=re.S):
            current = None
            for raw in block.replace("\\\n", " ").splitlines():
                text = raw.split("  #")[0].split(" # ")[0].rstrip()
                stripped = text.strip()
                words = stripped.split()
                if words and words[0].endswith("jitroute") and not raw[:1].isspace():
                    current = [page.name, stripped]
                    found.append(current)
                elif current is not None and raw[:1].isspace() and stripped:
                    current[1] += " " + stripped
                else:
                    current = None
    return [(page, command) for page, command in found]


def test_every_jitroute_command_in_the_manual_names_a_real_command_and_real_options():
    import typer

    from cli.main import app

    root = typer.main.get_command(app)
    lines = _command_lines()
    assert any(command.startswith("jitroute route --from") for _, command in lines)
    assert len(lines) >= 20
    wrong = []
    for page, command in lines:
        words = command.split()[1:]
        node, path = root, ["jitroute"]
        while words and words[0] in getattr(node, "commands", {}):
            node = node.commands[words[0]]
            path.append(words.pop(0))
        if hasattr(node, "commands") and node is not root:
            wrong.append(f"{page}: `{command}`: {' '.join(path)} needs a sub-command")
            continue
        known = {name for param in node.params for name in (*param.opts, *param.secondary_opts)} | {"--help"}
        for option in re.findall(r"(?<![\w-])--[a-z][a-z0-9-]*", command):
            if option not in known:
                wrong.append(f"{page}: `{command}`: {' '.join(path)} has no option {option}")
    assert not wrong, "\n".join(wrong)
