"""The package's layers hold: no module imports one from a layer above its own, at the top of the file
or inside a function (docs/architecture.md draws the same picture)."""

from __future__ import annotations

import ast
import pathlib

import pytest

SRC = pathlib.Path(__file__).resolve().parents[1] / "src" / "fetch"

LAYERS: tuple[tuple[str, ...], ...] = (
    ("fetch._environ", "fetch._gl", "fetch._processes", "fetch._progress", "fetch._durable", "fetch._confine",
     "fetch.errors", "fetch.timing", "fetch.stopping", "fetch._references"),
    ("fetch.robot",),
    ("fetch.scene",),
    ("fetch.observation", "fetch.tasks"),
    ("fetch.looks", "fetch.rendering", "fetch.camera_obs", "fetch.compiled", "fetch.env", "fetch"),
    ("fetch.vector",),
    ("fetch.dataset", "fetch.experts"),
    ("fetch.generate",),
    ("fetch.teleop",),
    ("fetch.learn",),
    ("fetch.cli", "fetch.collect", "fetch._docs"),
)
"""Bottom to top. A module belongs to the layer of its longest listed prefix; `fetch` itself (the
package's `__init__`: the env registrations) sits with the env."""


def layer(module: str) -> int:
    best, found = -1, None
    for i, names in enumerate(LAYERS):
        for name in names:
            if (module == name or module.startswith(name + ".")) and len(name) > best:
                best, found = len(name), i
    if found is None:
        raise AssertionError(f"{module} is in no layer: add it to LAYERS (and docs/architecture.md)")
    return found


def module_name(path: pathlib.Path) -> str:
    parts = list(path.relative_to(SRC.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def imports(path: pathlib.Path) -> list[tuple[int, str]]:
    """(line, module) of every `fetch` import in the file, wherever it is; `from fetch import x` counts
    as `fetch.x` where x is a module, else as `fetch`."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names if a.name.split(".")[0] == "fetch"]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module \
                and node.module.split(".")[0] == "fetch":
            for a in node.names:
                sub = f"{node.module}.{a.name}"
                is_module = (SRC.parent / sub.replace(".", "/")).with_suffix(".py").exists() \
                    or (SRC.parent / sub.replace(".", "/")).is_dir()
                found.append((node.lineno, sub if is_module else node.module))
    return found


MODULES = sorted(SRC.rglob("*.py"))


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(SRC)))
def test_no_module_imports_from_a_layer_above_its_own(path: pathlib.Path) -> None:
    own = module_name(path)
    upward = [f"line {line}: {target} (layer {layer(target)}, above {own}'s {layer(own)})"
              for line, target in imports(path) if layer(target) > layer(own)]
    assert not upward, "\n".join(upward)


def test_the_checker_finds_an_upward_import(tmp_path: pathlib.Path) -> None:
    """The rule can fail: an import of the CLI from inside a dataset function is caught."""
    fake = SRC / "dataset" / "reader.py"
    source = tmp_path / "reader.py"
    source.write_text("def f():\n    from fetch.cli import main\n    return main\n")
    found = imports(source)
    assert found == [(2, "fetch.cli")] and layer("fetch.cli") > layer(module_name(fake))


def test_every_layer_is_drawn_in_the_architecture_page() -> None:
    page = (SRC.parents[1] / "docs" / "architecture.md").read_text()
    for names in LAYERS:
        for name in names:
            if name != "fetch":
                shown = name.removeprefix("fetch.")
                assert shown in page, f"docs/architecture.md does not mention {shown}"
