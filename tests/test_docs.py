"""The README says what the code does: generated tables match, the first two commands are the set-up."""

from __future__ import annotations

import pathlib
import re

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
