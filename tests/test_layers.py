"""The package's layers hold: no module imports one from a layer above its own, at the top of the file
or inside a function, and no module imports itself through others, sub-packages' modules included
(docs/architecture.md draws the same picture)."""

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
    ("fetch.dataset.render",),
    ("fetch.dataset", "fetch.experts"),
    ("fetch.dataset.replay",),
    ("fetch.dataset.exports", "fetch.dataset.page"),
    ("fetch.generate",),
    ("fetch.teleop",),
    ("fetch.learn",),
    ("fetch.cli", "fetch.commands", "fetch.collect", "fetch._docs", "fetch.testing"),
)
"""Bottom to top. A module belongs to the layer of its longest listed prefix; `fetch` itself (the
package's `__init__`: the env registrations) sits with the env, and `fetch.dataset`'s own modules (storage
and validation) between its sub-packages: the images of saved states below (the writer renders a demo's
missing images), replay above, exports and the page on top."""


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


def import_graph() -> dict[str, set[str]]:
    """Each module's `fetch` imports, wherever they are in the file (`imports`)."""
    return {module_name(path): {target for _, target in imports(path)} for path in MODULES}


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """A chain of imports that comes back to where it started (`[a, b, a]`), or None. A package's
    `__init__` counts as the module named by the package, and only the imports written count (not the
    parent packages Python runs first)."""
    done: set[str] = set()
    for start in sorted(graph):
        if start in done:
            continue
        path, stack = [start], [iter(sorted(graph[start]))]
        while stack:
            target = next(stack[-1], None)
            if target is None:
                stack.pop()
                done.add(path.pop())
            elif target in path:
                return path[path.index(target):] + [target]
            elif target not in done and target in graph:
                path.append(target)
                stack.append(iter(sorted(graph[target])))
    return None


def test_no_import_cycle() -> None:
    """No module imports itself through others, not even inside a function, in a sub-package or across
    sub-packages of one layer (`dataset/npz.py -> replay.py -> recordings.py -> npz.py` was one)."""
    cycle = find_cycle(import_graph())
    assert cycle is None, "import cycle: " + " -> ".join(cycle or [])


def test_the_cycle_check_finds_a_cycle() -> None:
    """The rule can fail: a chain through a sub-package back to its start is found, a chain that ends is not."""
    graph = {"fetch.dataset.npz": {"fetch.dataset.schema", "fetch.dataset.replay.check"},
             "fetch.dataset.schema": set(),
             "fetch.dataset.replay.check": {"fetch.dataset.replay.recordings"},
             "fetch.dataset.replay.recordings": {"fetch.dataset.npz", "fetch.dataset.schema"}}
    assert find_cycle(graph) == ["fetch.dataset.npz", "fetch.dataset.replay.check", "fetch.dataset.replay.recordings",
                                 "fetch.dataset.npz"]
    graph["fetch.dataset.replay.recordings"] = {"fetch.dataset.schema"}
    assert find_cycle(graph) is None


COMMAND_LAYER = ("fetch.cli", "fetch.commands")
"""The command layer: the only modules that parse a command line (`import argparse`)."""


def argparse_imports(path: pathlib.Path) -> list[int]:
    """The lines of every `import argparse` (or `from argparse import ...`) in the file, wherever it is."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found += [node.lineno for a in node.names if a.name.split(".")[0] == "argparse"]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and (node.module or "").split(".")[0] == "argparse":
            found.append(node.lineno)
    return found


def may_parse_arguments(module: str) -> bool:
    return any(module == n or module.startswith(n + ".") for n in COMMAND_LAYER)


def test_only_the_command_layer_imports_argparse() -> None:
    """The library takes typed requests, never a parsed command line: argparse is for `fetch.commands`."""
    found = [f"{module_name(path)} (line {', '.join(map(str, lines))})" for path in MODULES
             if (lines := argparse_imports(path)) and not may_parse_arguments(module_name(path))]
    assert not found, f"argparse imported by {'; '.join(found)}: flags belong in the command layer, " \
                      f"{', '.join(COMMAND_LAYER)}; the library takes a typed request"


def test_the_checker_finds_argparse_in_a_library_module(tmp_path: pathlib.Path) -> None:
    """The rule can fail: argparse imported inside a function of a library module (teleop) is caught, as is
    `from argparse import`; the command layer's is allowed."""
    source = tmp_path / "build.py"
    source.write_text("import os\n\n\ndef f():\n    import argparse\n    return argparse.Namespace()\n\n\n"
                      "def g():\n    from argparse import Namespace\n    return Namespace()\n")
    assert argparse_imports(source) == [5, 10]
    assert not may_parse_arguments("fetch.teleop.build") and not may_parse_arguments("fetch.commandsx")
    assert not may_parse_arguments("fetch.dataset.edit") and not may_parse_arguments("fetch.dataset.exports.exporters")
    assert may_parse_arguments("fetch.commands.collect") and may_parse_arguments("fetch.cli")


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
                assert shown in page or shown.replace(".", "/") in page, \
                    f"docs/architecture.md does not mention {shown}"
