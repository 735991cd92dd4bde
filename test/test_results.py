"""Results kept as data (tmgwr_agent.experiments.results, ``./tmgwr results``).

* Every results table between ``<!-- results:NAME -->`` markers in README.md and docs/ is
  what its JSON under results/ gives: regenerated in memory and compared; every figure of
  docs/figures/ names the result it was drawn from, and that is the result its file holds.
* Every committed results file carries its provenance (command, commit, cores, load).
* ``record`` runs a real experiment and keeps its JSON with that provenance.
* The documentation builds with ``mkdocs build --strict`` (CI also runs ``make docs``).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys

import pytest
from small_mazes import SMALL

from tmgwr_agent.experiments import results

ROOT = results.ROOT


def test_every_table_in_readme_and_docs_equals_its_json():
    stale = results.stale_tables(ROOT)
    assert not stale, ("tables differ from results/*.json (run ./tmgwr results):\n"
                       + "\n".join(stale))


def test_every_table_is_shown_and_every_marker_is_known():
    shown = set()
    for path in results.doc_files(ROOT):
        shown |= {m.group(2) for m in results.MARKER.finditer(path.read_text())}
    assert shown == set(results.TABLES), (shown, set(results.TABLES))
    readme = (ROOT / "README.md").read_text()
    assert "<!-- results:headline -->" in readme


def test_the_comparison_fails_on_a_changed_figure(tmp_path):
    shutil.copytree(ROOT / "results", tmp_path / "results",
                    ignore=shutil.ignore_patterns("tune", "*.png"))
    readme = (ROOT / "README.md").read_text()
    (tmp_path / "README.md").write_text(readme)
    assert results.stale_tables(tmp_path) == []
    doc = json.loads((tmp_path / "results" / "env_change_a.json").read_text())
    doc["result"]["oracle_steps"] += 1
    (tmp_path / "results" / "env_change_a.json").write_text(json.dumps(doc))
    assert results.stale_tables(tmp_path) == ["README.md: headline"]
    results.render(tmp_path, figures=False)
    assert results.stale_tables(tmp_path) == []
    assert f"oracle {doc['result']['oracle_steps']}" in (tmp_path / "README.md").read_text()


def test_every_figure_is_drawn_from_its_json_as_it_is():
    stale = results.stale_figures(ROOT)
    assert not stale, ("figures differ from results/*.json (run ./tmgwr results):\n"
                       + "\n".join(stale))


def test_a_figure_drawn_from_another_result_or_left_over_is_named(tmp_path):
    (tmp_path / "results").mkdir()
    for name in ("env_change_a", "goal_change"):
        shutil.copy(ROOT / "results" / f"{name}.json", tmp_path / "results")
    figures = tmp_path / results.FIGURES_DIR
    assert results.stale_figures(tmp_path) == [
        "docs/figures/env_change_a.png: missing", "docs/figures/goal_change.png: missing"]
    results.render(tmp_path)
    assert results.stale_figures(tmp_path) == []
    doc = json.loads((tmp_path / "results" / "env_change_a.json").read_text())
    doc["result"]["oracle_steps"] += 1
    (tmp_path / "results" / "env_change_a.json").write_text(json.dumps(doc))
    (tmp_path / "results" / "goal_change.json").unlink()
    assert results.stale_figures(tmp_path) == [
        "docs/figures/env_change_a.png: not drawn from results/env_change_a.json as it is",
        "docs/figures/goal_change.png: no results file draws it"]
    results.render(tmp_path)
    (figures / "goal_change.png").unlink()
    assert results.stale_figures(tmp_path) == []


def test_an_unknown_marker_or_a_missing_file_is_named(tmp_path):
    (tmp_path / "results").mkdir()
    (tmp_path / "README.md").write_text("<!-- results:nope -->\n<!-- /results:nope -->\n")
    with pytest.raises(results.ResultsError, match="README.md: unknown results table 'nope'"):
        results.stale_tables(tmp_path)
    (tmp_path / "README.md").write_text("<!-- results:goal-change -->\n"
                                        "<!-- /results:goal-change -->\n")
    with pytest.raises(results.ResultsError, match="results/goal_change.json is missing"):
        results.stale_tables(tmp_path)


@pytest.mark.parametrize("path", sorted((ROOT / "results").glob("*.json")),
                         ids=lambda p: p.name)
def test_every_results_file_records_its_provenance(path):
    doc = json.loads(path.read_text())
    assert doc["command"].startswith("./tmgwr ")
    assert re.fullmatch(r"[0-9a-f]{40}", doc["commit"]), doc["commit"]
    assert doc["dirty"] is False, f"{path.name} was made from uncommitted sources"
    m = doc["machine"]
    assert isinstance(m["cores"], int) and m["cores"] > 0
    assert len(m["load_start"]) == 3 and len(m["load_end"]) == 3
    assert "scenario" in doc["result"] or "graph" in doc["result"]


def _cli(cwd, *args):
    return subprocess.run([sys.executable, "-m", "tmgwr_agent.cli", *args], cwd=cwd,
                          capture_output=True, text=True, timeout=600)


def test_record_runs_the_command_and_keeps_its_provenance(tmp_path):
    maze = tmp_path / "small.txt"
    maze.write_text(SMALL)
    argv = ["experiment", "env-change", "--maze", str(maze), "--agents", "tmgwr",
            "--trials", "1", "--quiet"]
    out = results.record("small", argv, root=tmp_path)
    doc = json.loads(out.read_text())
    assert doc["command"] == "./tmgwr " + " ".join(argv)
    assert doc["machine"]["cores"] >= 1 and len(doc["machine"]["load_end"]) == 3
    assert doc["result"]["scenario"] == "env-change"
    assert doc["result"]["maze"] == str(maze)
    assert list(doc["result"]["agents"]) == ["tmgwr"]


def test_again_records_a_file_by_its_own_command(tmp_path):
    maze = tmp_path / "small.txt"
    maze.write_text(SMALL)
    argv = ["experiment", "env-change", "--maze", str(maze), "--agents", "tmgwr",
            "--trials", "1", "--quiet"]
    first = json.loads(results.record("small", argv, root=tmp_path).read_text())
    (tmp_path / "results" / "small.json").write_text(json.dumps({**first, "started": "x"}))
    with pytest.raises(results.ResultsError, match="no results/other.json"):
        results.again(["small"], root=tmp_path, skip=("other",))
    [out] = results.again([], root=tmp_path)
    doc = json.loads(out.read_text())
    assert doc["command"] == first["command"] and doc["started"] != "x"
    assert doc["result"]["agents"] == first["result"]["agents"]     # same seed, same figures
    assert results.again(["small"], root=tmp_path, skip=("small",)) == []


def test_record_refuses_what_it_cannot_keep(tmp_path):
    r = _cli(ROOT, "results", "record", "x", "--", "experiment", "env-change", "--json",
             str(tmp_path / "x.json"))
    assert r.returncode == 2 and "record sets --json itself" in r.stderr
    r = _cli(ROOT, "results", "record", "Bad/Name", "--", "experiment", "env-change")
    assert r.returncode == 2 and "use [a-z0-9_-] only" in r.stderr
    r = _cli(ROOT, "results", "record", "x", "--", "up")
    assert r.returncode == 2 and "record runs `experiment ...` or `bench ...`" in r.stderr


def test_results_check_passes_on_the_repository():
    r = _cli(ROOT, "results", "--check")
    assert r.returncode == 0, r.stderr


def test_docs_build_in_strict_mode(tmp_path):
    """`make docs` (CI runs it too): a broken link or reference fails the build."""
    r = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--quiet",
                        "--site-dir", str(tmp_path / "site")], cwd=ROOT,
                       capture_output=True, text=True, timeout=600,
                       env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    assert r.returncode == 0, r.stdout + r.stderr
    assert (tmp_path / "site" / "graph" / "index.html").is_file()
    api = (tmp_path / "site" / "api" / "core" / "index.html").read_text()
    assert "tmgwr_agent.core.motivation" in api
