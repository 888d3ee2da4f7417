"""The docs say what the code does and nothing that went wrong before: generated tables match, every code
block is closed, no paragraph is said twice, every relative link and `#anchor` resolves, the guide holds no
date, commit hash or scratch path, every `gym-fetch` command line in a shell block parses with the real
parser, and every Python snippet in the README and the docs runs as written.

Pages: README.md and docs/*.md are the guide; docs/results/*.md are the results pages, which may carry one
"measured on" date. Each check is a function from a page's text to its problems, "file:line: what", and a
negative test feeds it a bad sample."""

from __future__ import annotations

import argparse
import ast
import contextlib
import importlib.util
import io
import pathlib
import re
import shlex
import subprocess
import sys
from collections.abc import Iterator

import pytest

from fetch import ENV_IDS, _docs

ROOT = pathlib.Path(__file__).parents[1]
README = (ROOT / "README.md").read_text()
GUIDE = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
RESULTS = sorted((ROOT / "docs" / "results").glob("*.md"))
PAGES = [*GUIDE, *RESULTS]


def _name(page: pathlib.Path) -> str:
    return page.relative_to(ROOT).as_posix()


def _ids(pages: list[pathlib.Path]) -> list[str]:
    return [_name(page) for page in pages]


# ---- reading a page: which lines are code, which are prose ----

FENCE = re.compile(r"^\s*(`{3,}|~{3,})(.*)$")


def _lines(text: str) -> Iterator[tuple[int, str, str | None]]:
    """(line number, line, the open block's info string or None in prose); fence lines are given as code
    ("fence"). An unclosed block runs to the end of the page, as GitHub renders it."""
    fence: str | None = None
    info: str | None = None
    for number, line in enumerate(text.splitlines(), 1):
        match = FENCE.match(line)
        if fence is None and match:
            fence, info = match[1], (match[2].split() or [""])[0]  # ```bash title="x": bash
            yield number, line, "fence"
        elif fence is not None and match and match[1].startswith(fence) and not match[2].strip():
            fence = info = None
            yield number, line, "fence"
        else:
            yield number, line, info


def fence_problems(name: str, text: str) -> list[str]:
    """An opening fence must be closed by a bare fence: a fence with an info string inside an open block
    (```python where ``` was meant) or a block open at the end turns the rest of the page inside out."""
    problems, opened = [], None
    for number, line in enumerate(text.splitlines(), 1):
        match = FENCE.match(line)
        if not match:
            continue
        if opened is None:
            opened = (number, match[1])
        elif match[1].startswith(opened[1][0] * len(opened[1])) and not match[2].strip():
            opened = None
        else:
            problems.append(f"{name}:{number}: a fence with {match[2].strip()!r} inside the block opened at line "
                            f"{opened[0]} (that block is not closed)")
            opened = (number, match[1])
    if opened is not None:
        problems.append(f"{name}:{opened[0]}: this code block is never closed")
    return problems


# ---- paragraphs said twice ----

LIST_ITEM = re.compile(r"^\s*(?:[-*+]|\d+[.)])\s+")


def _paragraphs(text: str) -> Iterator[tuple[int, str]]:
    """(first line, text with whitespace normalised) of each prose paragraph and list item, at least 40
    characters; code blocks, tables, headings, comments and generated blocks are left out."""
    start, words, generated = 0, [], False
    for number, line, block in [*_lines(text), (0, "", "end")]:
        stripped = line.strip()
        if block is None and re.fullmatch(r"<!-- \w+:(begin|end) -->", stripped):
            generated = stripped.endswith(":begin -->")
        prose = block is None and not generated and stripped and not stripped.startswith(("|", "#", "<!--"))
        if not prose or LIST_ITEM.match(line):  # the paragraph so far ends here
            paragraph = " ".join(" ".join(words).split())
            if len(paragraph) >= 40:
                yield start, paragraph
            words = []
        if prose:
            start = start if words else number
            words.append(LIST_ITEM.sub("", line))


def repeated_paragraphs(pages: dict[str, str], across: bool = True) -> list[str]:
    """A paragraph said twice in one page, or (`across`) in two pages: one fact, one place."""
    first: dict[str, str] = {}
    problems = []
    for name, text in pages.items():
        seen_here: dict[str, int] = {}
        for number, paragraph in _paragraphs(text):
            if paragraph in seen_here:
                problems.append(f"{name}:{number}: repeats the paragraph at line {seen_here[paragraph]}: "
                                f"{paragraph[:70]}...")
            elif across and paragraph in first:
                problems.append(f"{name}:{number}: repeats {first[paragraph]}: {paragraph[:70]}...")
            seen_here.setdefault(paragraph, number)
        for paragraph, number in seen_here.items():
            first.setdefault(paragraph, f"{name}:{number}")
    return problems


# ---- links and anchors ----

LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^()\s<>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
HTML_LINK = re.compile(r"""<(?:a|img)\b[^>]*?\b(?:href|src)=["']([^"']+)["']""")
REFERENCE = re.compile(r"^ {0,3}\[[^\]]+\]:\s*<?([^\s>]+)")  # [name]: target


def _prose(text: str) -> Iterator[tuple[int, str]]:
    """(line number, line) outside code blocks, with inline code spans blanked."""
    for number, line, block in _lines(text):
        if block is None:
            yield number, re.sub(r"`+[^`]*`+", lambda m: " " * len(m[0]), line)


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: the rendered text lowercased, punctuation but `-` and `_` dropped,
    each space a `-`."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)  # a link: its text
    text = re.sub(r"<[^>]+>", "", text).replace("`", "").strip().lower()
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def anchors(text: str) -> set[str]:
    """Every `#anchor` a page has: its headings' slugs (a repeated one gets -1, -2, ...) and explicit
    `id=`/`name=` attributes."""
    found: set[str] = set()
    counts: dict[str, int] = {}
    for _, line, block in _lines(text):
        heading = block is None and re.match(r"^ {0,3}#{1,6}\s+(.*?)(?:\s+#+)?\s*$", line)
        if heading:
            base = slug(heading[1])
            found.add(base if base not in counts else f"{base}-{counts[base]}")
            counts[base] = counts.get(base, 0) + 1
    found |= set(re.findall(r"""<[^>]*\b(?:id|name)=["']([^"']+)["']""", text))
    return found


def link_problems(page: pathlib.Path, text: str) -> list[str]:
    """A relative link (or image) to a file that does not exist, or to an `#anchor` its page lacks."""
    problems = []
    raw = text.splitlines()
    for number, line in _prose(text):
        original = raw[number - 1]  # `line` has its inline code blanked: the targets are read from the page
        for match in [*LINK.finditer(line), *HTML_LINK.finditer(line), *REFERENCE.finditer(line)]:
            target = original[match.start(1):match.end(1)]
            if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.I):  # https:, mailto:
                continue
            path, _, anchor = target.partition("#")
            linked = (page.parent / path).resolve() if path else page
            where = f"{_name(page) if page.is_relative_to(ROOT) else page.name}:{number}"
            if not linked.exists():
                problems.append(f"{where}: links to {target}, and {path} does not exist")
            elif anchor and linked.suffix == ".md" and anchor not in anchors(linked.read_text()):
                problems.append(f"{where}: links to {target}, and {linked.name} has no heading with that anchor")
    return problems


# ---- no dates, commit hashes or scratch paths in the guide ----

MONTH = ("(?:Jan(?:uary)?|Feb(?:ruary)?|Mar(?:ch)?|Apr(?:il)?|May|June?|July?|Aug(?:ust)?|Sep(?:t|tember)?|"
         "Oct(?:ober)?|Nov(?:ember)?|Dec(?:ember)?)")
DATE = re.compile(rf"\b(?:(?:19|20)\d\d-[01]\d-[0-3]\d|(?:[0-3]?\d\s+)?{MONTH}\.?\s+(?:[0-3]?\d,\s+)?(?:19|20)\d\d)\b")
# A commit: 7 to 40 lowercase hex digits standing as a word, with a digit and a letter in it (so no plain
# number, no word such as "defaced"); not after "#" (a colour). A sha256 (64) is not a commit.
HASH = re.compile(r"(?<![#\w-])(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}(?![\w-])")
SCRATCH = re.compile(r"(?<![\w.])/tmp/|(?<![\w.])/var/tmp/")


def stale_problems(name: str, text: str, results_page: bool = False) -> list[str]:
    """A date, a commit hash or a /tmp/ path in a guide page, code blocks included: the guide says how
    things are, and git keeps the history. A results page may carry one date, on its "measured on" line."""
    problems = []
    dated = []
    for number, line in enumerate(text.splitlines(), 1):
        for date in DATE.findall(line):
            if results_page and "measured" in line.lower():
                dated.append(number)
            else:
                problems.append(f"{name}:{number}: a date ({date}) in a "
                                + ("results page outside its 'measured on' line" if results_page else "guide page"))
        problems += [f"{name}:{number}: a commit hash ({h})" for h in HASH.findall(line)]
        problems += [f"{name}:{number}: a scratch path (/tmp/)" for _ in SCRATCH.findall(line)]
    if len(set(dated)) > 1:
        problems.append(f"{name}:{dated[1]}: a second 'measured on' date (first at line {dated[0]})")
    return problems


# ---- every documented command line parses ----

SHELL_BLOCKS = {"bash", "sh", "shell", "console", "zsh"}
PLACEHOLDER = re.compile(r"^(?:[A-Z][A-Z0-9_]*(?:[/:.][A-Za-z0-9_]*)*|\$\{?\w+\}?|\.\.\.|PLACEHOLDER)$")
SEPARATORS = {"|", "||", "&&", ";", "&", "(", ")", "|&"}


def shell_lines(text: str) -> Iterator[tuple[int, str]]:
    """(first line, command) of each command line in a ```bash / sh / shell / console block: `\\`
    continuations joined; in a console block only the lines after a `$ ` prompt."""
    pending: tuple[int, str] | None = None
    for number, line, block in _lines(text):
        if block not in SHELL_BLOCKS:
            if pending:
                yield pending
            pending = None
            continue
        if pending is None:
            if block == "console":
                if not line.startswith("$ "):
                    continue
                line = line[2:]
            pending = (number, "")
        joined = pending[1] + line
        if joined.rstrip().endswith("\\"):
            pending = (pending[0], joined.rstrip()[:-1] + " ")
        else:
            yield pending[0], joined
            pending = None
    if pending:
        yield pending


def gym_fetch_calls(command: str) -> list[list[str]]:
    """The arguments of each `gym-fetch` call in a shell command line: through pipes, `&&`, `;`,
    environment-variable prefixes, `.venv/bin/`, `python -m fetch.cli`, comments and redirections; a
    `<placeholder>` reads as one word."""
    command = re.sub(r"<[\w./:-]+>", "PLACEHOLDER", command)
    lexer = shlex.shlex(command, posix=True, punctuation_chars=True)
    lexer.whitespace_split = True
    tokens = list(lexer)
    calls, segment = [], []
    for token in [*tokens, ";"]:
        if token not in SEPARATORS:
            segment.append(token)
            continue
        words = segment
        segment = []
        for i, word in enumerate(words):
            if word.rsplit("/", 1)[-1] == "gym-fetch":
                args = words[i + 1:]
            elif word == "-m" and i and "python" in words[i - 1] and words[i + 1:i + 2] in (["fetch.cli"], ["fetch"]):
                args = words[i + 2:]
            else:
                continue
            cut = next((j for j, arg in enumerate(args) if arg and set(arg) <= set("<>&")), len(args))
            if cut and cut < len(args) and args[cut - 1] in ("1", "2") and args[cut] == ">&":
                cut -= 1
            calls.append(args[:cut])
            break
    return calls


def _open_parser() -> argparse.ArgumentParser:
    """`gym-fetch`'s own parser, with a placeholder (`DATASET`, `RUN`, `$OUT`, `<path>`) taken for any value
    whatever its type or choices: what a line must get right is the command, the flags and the literal
    values."""
    from fetch.cli import _parser

    class Choices(list):  # type: ignore[type-arg]
        def __contains__(self, value: object) -> bool:
            return bool(PLACEHOLDER.match(str(value))) or super().__contains__(value)

    def open_type(convert):  # type: ignore[no-untyped-def]  # noqa: ANN001, ANN202
        def read(text: str) -> object:
            return text if PLACEHOLDER.match(text) else convert(text)

        read.__name__ = getattr(convert, "__name__", "value")  # what argparse's message names
        return read

    parser = _parser()
    todo, seen = [parser], set()
    while todo:
        p = todo.pop()
        if id(p) in seen:
            continue
        seen.add(id(p))
        for action in p._actions:
            if isinstance(action, argparse._SubParsersAction):
                todo.extend(action.choices.values())
                continue
            if action.choices is not None:
                action.choices = Choices(action.choices)
            if callable(action.type):
                action.type = open_type(action.type)
    return parser


def command_problems(name: str, text: str, parser: argparse.ArgumentParser) -> tuple[list[str], int]:
    """Each `gym-fetch` command line in a shell block that the parser refuses (or shlex cannot split), with
    argparse's message; and how many were parsed."""
    problems, parsed = [], 0
    for number, command in shell_lines(text):
        try:
            calls = gym_fetch_calls(command)
        except ValueError as e:
            problems.append(f"{name}:{number}: does not split as a shell line ({e}): {command.strip()}")
            continue
        for args in calls:
            parsed += 1
            err = io.StringIO()
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                try:
                    env = getattr(parser.parse_args(args), "env", None)
                except SystemExit as e:
                    env = None
                    if e.code not in (0, None) and not err.getvalue().strip():
                        err.write(f"gym-fetch: exit {e.code}")
            why = (err.getvalue().strip().splitlines() or [""])[-1]
            if not why and isinstance(env, str) and not PLACEHOLDER.match(env) and env not in ENV_IDS:
                why = f"unknown env {env!r}; known: {', '.join(ENV_IDS)}"  # --env is checked when it runs
            if why:
                problems.append(f"{name}:{number}: gym-fetch {shlex.join(args)}\n    {why}")
    return problems, parsed


@pytest.fixture(scope="module")
def parser() -> argparse.ArgumentParser:
    return _open_parser()


# ---- the checks, over every page ----


def test_the_generated_tables_match_the_code() -> None:
    for name, page in _docs.PAGES.items():
        text = (ROOT / page).read_text()
        assert f"<!-- {name}:begin -->" in text, f"{page} lost its {name} table"
        assert _docs.render_blocks(text) == text, "run: python -m fetch._docs"


def test_the_readme_is_an_entry_point() -> None:
    assert len(README.splitlines()) <= 250


@pytest.mark.parametrize("page", PAGES, ids=_ids(PAGES))
def test_every_code_block_is_closed(page: pathlib.Path) -> None:
    """An unopened block (the README's quickstart once lost its ```python) turns the page inside out."""
    problems = fence_problems(_name(page), page.read_text())
    assert not problems, "\n".join(problems)


def test_no_paragraph_is_said_twice() -> None:
    """Within a page, or in two guide pages (a results page may repeat its own machine line elsewhere)."""
    problems = repeated_paragraphs({_name(page): page.read_text() for page in GUIDE})
    problems += repeated_paragraphs({_name(page): page.read_text() for page in RESULTS}, across=False)
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("page", PAGES, ids=_ids(PAGES))
def test_every_relative_link_and_anchor_resolves(page: pathlib.Path) -> None:
    problems = link_problems(page, page.read_text())
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("page", PAGES, ids=_ids(PAGES))
def test_the_guide_has_no_dates_commit_hashes_or_scratch_paths(page: pathlib.Path) -> None:
    problems = stale_problems(_name(page), page.read_text(), results_page=page in RESULTS)
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("page", PAGES, ids=_ids(PAGES))
def test_every_documented_command_line_parses(page: pathlib.Path, parser: argparse.ArgumentParser) -> None:
    problems, _ = command_problems(_name(page), page.read_text(), parser)
    assert not problems, "\n".join(problems)


def test_the_command_check_reads_the_readmes_commands(parser: argparse.ArgumentParser) -> None:
    """It cannot pass by finding nothing: every `gym-fetch` call in the README's shell blocks is parsed."""
    _, parsed = command_problems("README.md", README, parser)
    blocks = re.findall(r"^```bash\n(.*?)^```", README, re.S | re.M)
    assert parsed == sum(block.count("gym-fetch ") for block in blocks) >= 15


# ---- each check fails on what it is for ----


def test_the_fence_check_fails_on_an_unclosed_block() -> None:
    assert fence_problems("a.md", "```bash\nls\n```\n") == []
    assert fence_problems("a.md", "text\n```python\nx = 1\n```python\ny = 2\n```\n") == [
        "a.md:4: a fence with 'python' inside the block opened at line 2 (that block is not closed)"]
    assert fence_problems("a.md", "```bash\nls\n") == ["a.md:1: this code block is never closed"]


def test_the_repeat_check_fails_on_a_paragraph_said_twice() -> None:
    said = "The expert succeeds on every task but Slide, under DART noise,\nas measured."
    one = f"# A\n\n{said}\n\n| table | row that is long enough to count as a paragraph |\n"
    assert repeated_paragraphs({"a.md": one, "b.md": "# B\n\n- something else entirely, said only once here\n"}) == []
    assert repeated_paragraphs({"a.md": one, "b.md": f"Intro.\n\n{' '.join(said.split())}\n"}) == [
        "b.md:3: repeats a.md:3: The expert succeeds on every task but Slide, under DART noise, as meas..."]
    assert len(repeated_paragraphs({"a.md": f"{one}\n- {said}\n"})) == 1
    assert repeated_paragraphs({"a.md": one, "b.md": one}, across=False) == []


def test_github_anchors() -> None:
    text = "# Training and generating\n## `gym-fetch view`: a page, no server\n## Notes\n## Notes\n```\n# not\n```\n"
    assert anchors(text) == {"training-and-generating", "gym-fetch-view-a-page-no-server", "notes", "notes-1"}
    assert slug("What [the HUD](window.md) shows (1.5 s)") == "what-the-hud-shows-15-s"


def test_the_link_check_fails_on_a_missing_file_or_anchor(tmp_path: pathlib.Path) -> None:
    (tmp_path / "other.md").write_text("# Other page\n\n## The part\n")
    (tmp_path / "pic.png").write_bytes(b"")
    page = tmp_path / "page.md"
    page.write_text(text := ("# Page\n[ok](other.md) [ok](other.md#the-part) [ok](#page) ![ok](pic.png) [web](https://x.org/y)\n"
            "`[code](nowhere.md)`\n```\n[code](nowhere.md)\n```\n"
            "[bad](missing.md) and [bad](other.md#no-part) and [bad](#nothing) <img src=\"gone.png\">\n"
            "[ref]: other.md#the-part\n[ref2]: nowhere.md\n"))
    assert link_problems(page, text) == [
        "page.md:7: links to missing.md, and missing.md does not exist",
        "page.md:7: links to other.md#no-part, and other.md has no heading with that anchor",
        "page.md:7: links to #nothing, and page.md has no heading with that anchor",
        "page.md:7: links to gone.png, and gone.png does not exist",
        "page.md:9: links to nowhere.md, and nowhere.md does not exist"]


def test_the_stale_check_fails_on_a_date_a_hash_or_a_scratch_path() -> None:
    fine = ("Colour #a1b2c3d, 1234567 steps, a defaced word, mujoco 3.3.0, sha256 " + "ab12" * 16 + "\n"
            "--out runs/tmp/x, 2026 demos\n")
    assert stale_problems("g.md", fine) == []
    bad = "Run 2026-11-22.\nIn November 2026 we\nat commit 6114e56 and\nsaved to /tmp/run\n"
    assert stale_problems("g.md", bad) == [
        "g.md:1: a date (2026-11-22) in a guide page", "g.md:2: a date (November 2026) in a guide page",
        "g.md:3: a commit hash (6114e56)", "g.md:4: a scratch path (/tmp/)"]
    results = "Measured on 2026-11-22 (Linux, 2 cores).\n\n| a | b |\n"
    assert stale_problems("r.md", results, results_page=True) == []
    assert stale_problems("r.md", results + "Measured on 2026-11-23.\nRun 2026-11-24.\n", results_page=True) == [
        "r.md:5: a date (2026-11-24) in a results page outside its 'measured on' line",
        "r.md:4: a second 'measured on' date (first at line 1)"]


def test_command_lines_are_split_as_a_shell_would() -> None:
    text = ("```bash\nFOO=1 .venv/bin/gym-fetch info DATASET | head -3 && gym-fetch view D --out <path>  # note\n"
            "gym-fetch train demos/x \\\n    --out runs/x 2>&1 > log.txt\npip install x\n```\n"
            "gym-fetch not-in-a-block\n```console\n$ python -m fetch.cli --help\noutput gym-fetch x\n```\n")
    lines = list(shell_lines(text))
    assert [n for n, _ in lines] == [2, 3, 5, 9]
    assert [gym_fetch_calls(line) for _, line in lines] == [
        [["info", "DATASET"], ["view", "D", "--out", "PLACEHOLDER"]], [["train", "demos/x", "--out", "runs/x"]],
        [], [["--help"]]]


def test_the_command_check_fails_on_a_line_that_does_not_parse(parser: argparse.ArgumentParser) -> None:
    good = ("```bash\ngym-fetch collect --env TASK --device expert --episodes N --out <path>\n"
            "gym-fetch info demos/x && gym-fetch replay demos/x --check   # compare\n```\n")
    assert command_problems("g.md", good, parser) == ([], 3)
    bad = ("```bash\ngym-fetch collect --env Bin-pik-v2 --out demos/x\ngym-fetch colect --out x\n"
           "gym-fetch info demos/x \\\n  --no-such-flag\ngym-fetch info 'unclosed\n"
           "gym-fetch collect --episodes many\n```\n")
    problems, parsed = command_problems("g.md", bad, parser)
    assert [p.split(": gym-fetch")[0].split(": does not")[0] for p in problems] == [
        "g.md:2", "g.md:3", "g.md:4", "g.md:6", "g.md:7"], problems
    assert "unknown env 'Bin-pik-v2'" in problems[0] and "invalid choice: 'colect'" in problems[1]
    assert "--no-such-flag" in problems[2] and "No closing quotation" in problems[3] and "'many'" in problems[4]


# ---- the Python snippets run ----


def _snippets() -> list[tuple[str, str]]:
    """(where, code) of every ```python block in the README and the docs."""
    found = []
    for page in PAGES:
        text = page.read_text()
        for block in re.finditer(r"^```python\n(.*?)^```", text, re.S | re.M):
            found.append((f"{_name(page)}:{text[:block.start()].count(chr(10)) + 1}", block[1]))
    return found


SNIPPETS = _snippets()

NEEDS_BEHIND = {"fetch.learn": "torch"}
"""Our modules that import but cannot run without a package of an extra (`fetch.learn` acts with torch)."""


def test_the_snippets_are_found() -> None:
    pages = {where.split(":")[0] for where, _ in SNIPPETS}
    assert pages >= {"README.md", "docs/tasks.md", "docs/gymnasium_robotics.md"}


@pytest.mark.parametrize(("where", "code"), SNIPPETS, ids=[where for where, _ in SNIPPETS])
def test_the_python_snippets_run_as_written(where: str, code: str, tmp_path: pathlib.Path,
                                            request: pytest.FixtureRequest) -> None:
    """Each in a fresh interpreter, in an empty folder; one that needs a package this environment lacks
    (lerobot has its own) is skipped, saying which."""
    tree = ast.parse(code, where)
    imported = {alias.name for node in ast.walk(tree) if isinstance(node, ast.Import) for alias in node.names}
    imported |= {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom) and node.module}
    modules = {name.split(".")[0] for name in imported}
    modules |= {needed for name in imported for part, needed in NEEDS_BEHIND.items()
                if name == part or name.startswith(part + ".")}
    missing = sorted(name for name in modules if importlib.util.find_spec(name) is None)
    if missing:
        pytest.skip(f"{where} needs {', '.join(missing)}, not installed here")
    if "exports/drawer_open_lerobot" in code:  # what the export command beside it writes
        from fetch.dataset.exports.export import export_lerobot

        export_lerobot(request.getfixturevalue("reach_demos"), "me/fetch_drawer_open",
                       tmp_path / "exports" / "drawer_open_lerobot")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert run.returncode == 0, f"{where}:\n{run.stderr[-3000:]}"
