"""The README says what the code does: generated tables match, the first two commands are the set-up."""

from __future__ import annotations

import pathlib
import re

from fetch import _docs

ROOT = pathlib.Path(__file__).parents[1]
README = (ROOT / "README.md").read_text()


def test_readme_tables_match_the_code() -> None:
    assert _docs.render_blocks(README) == README, "run: python -m fetch._docs README.md"


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
