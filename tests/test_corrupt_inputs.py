"""Every tool on every kind of corrupt dataset: a one-line error naming the file, the demo and the
problem, exit 2, no traceback and nothing written; or a correct result. The corrupt files are made
here from a tiny real dataset (no binary fixtures); no case relies on file permissions (root
ignores them)."""

from __future__ import annotations

import dataclasses
import json
import pathlib
import re
import shutil
from collections.abc import Callable

import h5py
import numpy as np
import pytest

from fetch.cli import main
from fetch.dataset import open_dataset, validate

DEMO = "demo_1"  # every demo-level corruption hits the second demo: an error naming demo_0 is wrong
EPISODE = f"episodes/{DEMO}.hdf5"
INDEX = "demos.hdf5"


# -- the corruptions --------------------------------------------------------------------------------

def flip(path: pathlib.Path, offset: int) -> None:
    raw = bytearray(path.read_bytes())
    raw[offset] ^= 0xFF
    path.write_bytes(bytes(raw))


def signature(path: pathlib.Path, tag: bytes, which: int) -> int:
    """The offset of the `which`-th HDF5 structure signature `tag` (TREE, HEAP, SNOD, GCOL) in the file."""
    found = [m.start() for m in re.finditer(re.escape(tag), path.read_bytes())]
    assert found, (path, tag)
    return found[which]


def edit_data_attr(key: str, value: object) -> Callable[[pathlib.Path], None]:
    def corrupt(root: pathlib.Path) -> None:
        with h5py.File(root / INDEX, "r+") as f:
            f["data"].attrs[key] = value
    return corrupt


def edit_env_args(change: Callable[[dict[str, object]], object]) -> Callable[[pathlib.Path], None]:
    def corrupt(root: pathlib.Path) -> None:
        with h5py.File(root / INDEX, "r+") as f:
            env_args = json.loads(f["data"].attrs["env_args"])
            f["data"].attrs["env_args"] = change(env_args)
    return corrupt


def edit_demo(change: Callable[[h5py.Group], None]) -> Callable[[pathlib.Path], None]:
    def corrupt(root: pathlib.Path) -> None:
        with h5py.File(root / EPISODE, "r+") as f:
            change(f[DEMO])
    return corrupt


def replace(key: str, make: Callable[[np.ndarray], np.ndarray]) -> Callable[[h5py.Group], None]:
    def change(group: h5py.Group) -> None:
        new = make(group[key][()])
        del group[key]
        group.create_dataset(key, data=new)
    return change


def nan_at(a: np.ndarray) -> np.ndarray:
    a = a.copy()
    a[3, 1] = np.nan
    return a


def flip_inside_states(root: pathlib.Path) -> None:
    """The lowest byte of one saved state's value: the file stays sound, only a replay can tell."""
    with h5py.File(root / EPISODE, "r") as f:
        states = f[f"{DEMO}/states"]
        offset = states.id.get_offset() + (5 * states.shape[1] + 3) * states.dtype.itemsize
    flip(root / EPISODE, offset)


def cut_model_xml(root: pathlib.Path) -> None:
    with h5py.File(root / INDEX, "r+") as f:
        f["data"].attrs["model_xml"] = f["data"].attrs["model_xml"][:5000]


def push_model(with_hash: bool) -> Callable[[pathlib.Path], None]:
    """Another task's model stored as the dataset's (and, `with_hash`, that model's hash too)."""
    def corrupt(root: pathlib.Path) -> None:
        import gymnasium as gym

        push = gym.make("Push-v2").unwrapped
        with h5py.File(root / INDEX, "r+") as f:
            f["data"].attrs["model_xml"] = push.model_xml()
            if with_hash:
                f["data"].attrs["model_hash"] = push.model_hash()
    return corrupt


@dataclasses.dataclass(frozen=True)
class Case:
    corrupt: Callable[[pathlib.Path], None]
    problem: str
    """A regular expression the error (or info's problem line) must match: what is wrong."""
    demo: str | None = DEMO
    """The demo the error must name (None: the corruption is not in a demo)."""
    sound_file: bool = False
    """Only a replay can tell (a value changed inside an array): the other tools may succeed."""


CASES: dict[str, Case] = {
    # the file as a whole
    "format_version_one": Case(edit_data_attr("format_version", "one"), "format_version", demo=None),
    "index_flip_attrs": Case(lambda r: flip(r / INDEX, signature(r / INDEX, b"GCOL", 0)),
                             "cannot be read", demo=None),
    "index_flip_masks": Case(lambda r: flip(r / INDEX, signature(r / INDEX, b"HEAP", -1)),
                             "cannot be read", demo=None),
    "index_truncated": Case(lambda r: (r / INDEX).write_bytes((r / INDEX).read_bytes()[:5000]),
                            "not a readable HDF5 file", demo=None),
    "unknown_env": Case(edit_env_args(lambda a: json.dumps({**a, "env_name": "Reach-v9"})), "Reach-v9", demo=None),
    "env_args_not_json": Case(edit_data_attr("env_args", '{"env_name": "Reach-v2", "env_kwargs": {'), "env_args",
                              demo=None),
    "bad_env_kwargs": Case(edit_env_args(lambda a: json.dumps({**a, "env_kwargs": {"no_such_option": 1}})),
                           "no_such_option", demo=None),
    "bad_env_kwargs_value": Case(edit_env_args(lambda a: json.dumps({**a, "env_kwargs": {"reward_type": "bogus"}})),
                                 "bogus", demo=None),
    "model_xml_corrupt": Case(cut_model_xml, "model_xml", demo=None),
    "model_hash_missing": Case(lambda r: edit_data_attr("model_hash", "")(r), "model_hash", demo=None),
    "total_abc": Case(edit_data_attr("total", "abc"), "total", demo=None),
    "attempts_abc": Case(edit_data_attr("attempts", "abc"), "attempts", demo=None),
    "settings_not_object": Case(edit_data_attr("settings", "[1, 2]"), "settings", demo=None),
    # one demo's file
    "episode_flip_superblock": Case(lambda r: flip(r / EPISODE, 0), "cannot be read"),
    "episode_flip_group": Case(lambda r: flip(r / EPISODE, signature(r / EPISODE, b"TREE", 1)), "cannot be read"),
    "episode_flip_attrs": Case(lambda r: flip(r / EPISODE, signature(r / EPISODE, b"GCOL", 0)), "cannot be read"),
    "episode_flip_subgroup": Case(lambda r: flip(r / EPISODE, signature(r / EPISODE, b"SNOD", -1)),
                                  "cannot be read"),
    "episode_truncated": Case(lambda r: (r / EPISODE).write_bytes((r / EPISODE).read_bytes()[:20000]),
                              "cannot be read"),
    "episode_missing": Case(lambda r: (r / EPISODE).unlink(), "cannot be read"),
    "episode_flip_in_states": Case(flip_inside_states, "DEVIATES", sound_file=True),
    # one demo's content
    "missing_states": Case(edit_demo(lambda g: g.__delitem__("states")), "states"),
    "missing_num_samples": Case(edit_demo(lambda g: g.attrs.__delitem__("num_samples")), "num_samples"),
    "missing_seed": Case(edit_demo(lambda g: g.attrs.__delitem__("seed")), "seed"),
    "seed_abc": Case(edit_demo(lambda g: g.attrs.__setitem__("seed", "abc")), "seed"),
    "num_samples_abc": Case(edit_demo(lambda g: g.attrs.__setitem__("num_samples", "abc")), "num_samples"),
    "actions_3_columns": Case(edit_demo(replace("actions", lambda a: a[:, :3])), "actions"),
    "nan_action": Case(edit_demo(replace("actions", nan_at)), "actions.*NaN"),
    "obs_rows_short": Case(edit_demo(replace("obs/observation", lambda a: a[:-1])), "obs/observation"),
    "seed_2_64": Case(edit_demo(lambda g: g.attrs.__setitem__("seed", np.uint64(2**64 - 1))), "seed"),
    "nan_expert_action": Case(edit_demo(replace("expert_actions", nan_at)), "expert_actions"),
    "huge_expert_action": Case(edit_demo(replace("expert_actions", lambda a: a * 1e6)), "expert_actions"),
    "nan_reward": Case(edit_demo(replace("rewards", lambda a: np.where(np.arange(len(a)) == 3, np.nan, a))),
                       "rewards"),
    "rewards_5": Case(edit_demo(replace("rewards", lambda a: np.full_like(a, 5.0))), "rewards"),
    "reward_flipped": Case(edit_demo(replace("rewards", lambda a: np.where(np.arange(len(a)) == 3, -1.0 - a, a))),
                           r"rewards\[3\]"),
    "env_kwargs_dense": Case(edit_env_args(lambda a: json.dumps({**a, "env_kwargs": {"reward_type": "dense"}})),
                             "reward", demo=None),
    "model_xml_of_push": Case(push_model(with_hash=False), "model_xml", demo=None),
    "model_xml_and_hash_of_push": Case(push_model(with_hash=True), "model_xml", demo=None),
    "is_success_7": Case(edit_demo(replace("is_success", lambda a: np.full_like(a, 7))), "is_success"),
    "terminated_always": Case(edit_demo(replace("terminated", lambda a: np.ones_like(a))), "terminated"),
}


# -- the tools --------------------------------------------------------------------------------------

TOOLS: dict[str, list[str]] = {
    "info": ["info", "{d}"],
    "replay_check": ["replay", "{d}", "--check"],
    "replay_video": ["replay", "{d}", "--video", "{t}/v.gif", "--size", "16"],
    "render_obs": ["render-obs", "{d}", "--camera", "front", "--size", "16", "--workers", "1"],
    "merge": ["merge", "{d}", "{t}/other", "--out", "{t}/merged.hdf5"],
    "split": ["split", "{d}"],
    "export_npz": ["export", "{d}", "--to", "npz", "--out", "{t}/npz"],
    "export_minari": ["export", "{d}", "--to", "minari", "--dataset-id", "fetch/corrupt/test-v0"],
    "export_lerobot": ["export", "{d}", "--to", "lerobot", "--repo-id", "me/corrupt", "--out", "{t}/lerobot",
                       "--cameras", "front", "--image-size", "16"],
    "view": ["view", "{d}", "--out", "{t}/view", "--size", "16", "--workers", "1"],
    "generate": ["generate", "--source", "{d}", "--out", "{t}/generated", "--demos", "1", "--workers", "1"],
    "subtasks": ["subtasks", "{d}"],
    "train": ["train", "{d}", "--out", "{t}/run", "--steps", "2", "--hidden", "8"],
}
CHANGES_THE_DATASET = ("render_obs", "split")
NEEDS = {"export_minari": "minari", "export_lerobot": "av", "train": "torch"}
"""The module a tool needs that a test virtualenv may not have (the tool is then skipped there)."""


def snapshot(root: pathlib.Path) -> dict[str, bytes | None]:
    """Every file (with its bytes) and directory (None) under `root`, hidden ones too."""
    return {str(p.relative_to(root)): p.read_bytes() if p.is_file() else None for p in sorted(root.rglob("*"))}


def check_correct_result(tool: str, tmp: pathlib.Path, d: pathlib.Path, out: str) -> None:
    """What a tool that succeeded must have made (only for files only a replay can find fault with)."""
    if tool == "info":
        assert out.strip().endswith("valid"), out
    elif tool == "replay_video":
        assert (tmp / "v_demo_0.gif").stat().st_size and (tmp / "v_demo_1.gif").stat().st_size
    elif tool in ("render_obs", "split"):
        with open_dataset(d) as ds:
            assert validate(ds) == []
    elif tool == "merge":
        with open_dataset(tmp / "merged.hdf5") as ds:
            assert validate(ds) == [] and len(ds.demo_names) == 4
    elif tool == "export_npz":
        assert len(list((tmp / "npz").glob("*.npz"))) == 2
    elif tool == "export_minari":
        assert (tmp / "minari" / "fetch" / "corrupt" / "test-v0").is_dir()
    elif tool == "export_lerobot":
        assert (tmp / "lerobot" / "meta" / "info.json").is_file()
    elif tool == "view":
        assert (tmp / "view" / "index.html").is_file()
    elif tool == "generate":
        with open_dataset(tmp / "generated") as ds:
            assert validate(ds) == [] and len(ds.demo_names) == 1
    elif tool == "subtasks":
        assert "demo_1" in out, out
    elif tool == "train":
        assert (tmp / "run" / "checkpoint.pt").is_file()
    else:
        raise AssertionError(f"{tool} may not succeed on this file")


@pytest.mark.parametrize("tool", list(TOOLS))
@pytest.mark.parametrize("case", list(CASES))
def test_corrupt_input_is_refused_cleanly_or_handled(reach_demos: pathlib.Path, tmp_path: pathlib.Path, case: str,
                                                     tool: str, capsys: pytest.CaptureFixture[str],
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    if tool in NEEDS:
        pytest.importorskip(NEEDS[tool])
    if tool == "export_minari":
        monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    spec = CASES[case]
    d = tmp_path / "dataset"
    shutil.copytree(reach_demos, d)
    shutil.copytree(reach_demos, tmp_path / "other")  # merge's second, sound input
    spec.corrupt(d)
    argv = [a.format(d=d, t=tmp_path) for a in TOOLS[tool]]
    before = snapshot(tmp_path)
    capsys.readouterr()
    try:
        code = main(argv)
    except BaseException as e:  # noqa: BLE001 (any escape is the failure this test is about)
        pytest.fail(f"gym-fetch {' '.join(argv)} raised {e!r} instead of a one-line error")
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err, err
    after = snapshot(tmp_path)
    said = f"exit {code}; stdout: {out!r}; stderr: {err!r}"

    if code == 2:  # refused: one line naming the file, the demo and the problem; nothing written
        assert not spec.sound_file, f"a sound file was refused: {said}"
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith(f"gym-fetch {argv[0]}: error: "), said
        assert str(d) in lines[0], f"the error does not name the file: {said}"
        if spec.demo is not None:
            assert spec.demo in lines[0], f"the error does not name {spec.demo}: {said}"
        assert re.search(spec.problem, lines[0]), f"the error does not say {spec.problem!r}: {said}"
        assert after == before, f"files changed or appeared: {sorted(set(after) ^ set(before))}"
    elif code == 1 and tool == "info":  # the verdict INVALID, listing the problem
        assert not spec.sound_file and "INVALID" in out, said
        listed = [line for line in out.splitlines() if line.startswith("  - ")]
        assert any(re.search(spec.problem, line) and (spec.demo is None or spec.demo in line) for line in listed), said
        assert after == before
    elif code == 1 and tool == "replay_check":  # only a replay finds a changed value
        assert spec.sound_file and f"{DEMO}: " in out and "DEVIATES" in out, said
        assert after == before
    elif code == 0 and tool == "view" and not spec.sound_file:  # a page that shows each problem where it is
        import json

        html = (tmp_path / "view" / "index.html").read_text()
        tag = '<script id="summary" type="application/json">'
        summary = json.loads(html[html.index(tag) + len(tag):html.index("</script>", html.index(tag))])
        rows = {row["name"]: row for row in summary["demos"]}
        shown = [rows[spec.demo]["problem"]] if spec.demo in rows else \
            [*summary["problems"], *(row["problem"] for row in rows.values())] if spec.demo is None else []
        assert any(re.search(spec.problem, p) for p in shown), f"the page does not show {spec.problem!r}: {said}"
        assert {k: v for k, v in after.items() if k.startswith("dataset")} == \
            {k: v for k, v in before.items() if k.startswith("dataset")}
    elif code == 0 and spec.sound_file and tool != "replay_check":
        check_correct_result(tool, tmp_path, d, out)
        if tool not in CHANGES_THE_DATASET:
            assert {k: v for k, v in after.items() if k.startswith("dataset")} == \
                {k: v for k, v in before.items() if k.startswith("dataset")}
    else:
        pytest.fail(f"gym-fetch {' '.join(argv)}: neither a clean refusal nor a correct result: {said}")
