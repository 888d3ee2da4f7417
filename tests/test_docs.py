"""The README says what the code does: generated tables match, the first two commands are the set-up, and
every Python snippet in the README and the docs runs as written."""

from __future__ import annotations

import ast
import importlib.util
import pathlib
import re
import subprocess
import sys

import pytest

from fetch import _docs

ROOT = pathlib.Path(__file__).parents[1]
README = (ROOT / "README.md").read_text()


def test_the_generated_tables_match_the_code() -> None:
    for name, page in _docs.PAGES.items():
        text = (ROOT / page).read_text()
        assert f"<!-- {name}:begin -->" in text, f"{page} lost its {name} table"
        assert _docs.render_blocks(text) == text, "run: python -m fetch._docs"


def test_the_readme_is_an_entry_point_whose_links_resolve() -> None:
    """At most 250 lines; every page it links to exists, and so does every page those link to."""
    assert len(README.splitlines()) <= 250
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
    for page in pages:
        for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", page.read_text()):
            if "://" in target:
                continue
            assert (page.parent / target).exists(), f"{page.name} links to {target}, which does not exist"


def test_every_task_has_a_picture() -> None:
    import fetch

    for env_id in fetch.ENV_IDS:
        assert (ROOT / "docs" / "images" / f"{env_id}.png").is_file()
        assert f"docs/images/{env_id}.png" in README


def test_readme_starts_with_the_install_and_test_commands_ci_runs() -> None:
    first_block = re.search(r"```bash\n(.*?)```", README, re.S)
    assert first_block is not None
    install, test = first_block.group(1).strip().splitlines()
    assert "pip install" in install and "examples/demo.py" in install
    assert "pytest" in test
    ci = (ROOT / ".ci" / "run").read_text()
    assert install in ci and test in ci


PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def _snippets() -> list[tuple[str, str]]:
    """(where, code) of every ```python block in the README and the docs."""
    found = []
    for page in PAGES:
        text = page.read_text()
        for block in re.finditer(r"^```python\n(.*?)^```", text, re.S | re.M):
            found.append((f"{page.name}:{text[:block.start()].count(chr(10)) + 1}", block[1]))
    return found


SNIPPETS = _snippets()


def test_every_code_block_is_closed_and_the_snippets_are_found() -> None:
    """An unopened block (the README's quickstart once lost its ```python) turns the page inside out."""
    for page in PAGES:
        fences = [line for line in page.read_text().splitlines() if line.startswith("```")]
        assert len(fences) % 2 == 0, f"{page.name}: a code block is not closed (or not opened)"
        assert all(close == "```" for close in fences[1::2]), f"{page.name}: {fences}"
    assert {where.split(":")[0] for where, _ in SNIPPETS} >= {"README.md", "tasks.md", "gymnasium_robotics.md"}


@pytest.mark.parametrize(("where", "code"), SNIPPETS, ids=[where for where, _ in SNIPPETS])
def test_the_python_snippets_run_as_written(where: str, code: str, tmp_path: pathlib.Path,
                                            request: pytest.FixtureRequest) -> None:
    """Each in a fresh interpreter, in an empty folder; one that needs a package this environment lacks
    (lerobot has its own) is skipped, saying which."""
    tree = ast.parse(code, where)
    modules = {alias.name.split(".")[0] for node in ast.walk(tree) if isinstance(node, ast.Import)
               for alias in node.names}
    modules |= {node.module.split(".")[0] for node in ast.walk(tree)
                if isinstance(node, ast.ImportFrom) and node.module}
    missing = sorted(name for name in modules if importlib.util.find_spec(name) is None)
    if missing:
        pytest.skip(f"{where} needs {', '.join(missing)}, not installed here")
    if "exports/drawer_open_lerobot" in code:  # what the export command beside it writes
        from fetch.dataset.export import export_lerobot

        export_lerobot(request.getfixturevalue("reach_demos"), "me/fetch_drawer_open",
                       tmp_path / "exports" / "drawer_open_lerobot")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert run.returncode == 0, f"{where}:\n{run.stderr[-3000:]}"
