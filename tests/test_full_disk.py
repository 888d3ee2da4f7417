"""Every tool on a full disk (issue 38): one line of error, no traceback, its inputs untouched, no
half-written output (the old output intact), and a collector's summary counting only what is on disk.

A full disk is a real small file system: a tmpfs mounted in a user namespace (`unshare`; no root
needed where the kernel allows one), the inputs copied onto it, the rest filled but `leave` bytes."""

from __future__ import annotations

import dataclasses
import hashlib
import os
import pathlib
import re
import shlex
import shutil
import subprocess
import sys

import pytest

from fetch.dataset import open_dataset, validate

TOOL = [sys.executable, "-c", "import sys; from fetch.cli import main; sys.exit(main(sys.argv[1:]))"]

DISK = "disk"
PROGRESS = re.compile(r"^[\w -]+ \[[# ]+\] \d+/\d+ ")
"""A progress line (`fetch._progress.Bar`): a tool whose stderr is not a terminal writes one every few seconds."""
"""The tmpfs's mount point under the test's tmp_path; the tool runs with it as its working directory."""


@dataclasses.dataclass
class Run:
    """What a tool did on the small disk: its exit status and output, and the files it left there
    (copied out before the file system went away) beside the ones that were there before it ran."""

    rc: int
    stdout: str
    stderr: str
    before: dict[str, str]
    after: dict[str, str]
    left: pathlib.Path

    def one_line_error(self) -> str:
        err = "\n".join(line for line in self.stderr.strip().splitlines() if not PROGRESS.match(line))
        assert "Traceback" not in self.stderr + self.stdout, self.stderr
        assert self.rc == 2, (self.rc, self.stdout, err)
        assert len(err.splitlines()) == 1, err
        assert re.search("the disk is full|not enough disk space|No space left on device", err), err
        return err

    def inputs_untouched(self, new: frozenset[str] = frozenset()) -> None:
        """Every file that was there is there byte for byte; nothing else but `new` names."""
        assert {k: v for k, v in self.after.items() if k in self.before} == self.before
        assert set(self.after) - set(self.before) <= new, sorted(set(self.after) - set(self.before))


def _hashes(root: pathlib.Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def on_full_disk(tmp_path: pathlib.Path, args: list[str], inputs: dict[str, pathlib.Path] | None = None,
                 leave: int = 8192, size: str = "64m") -> Run:
    """Run `gym-fetch ARGS` in a tmpfs of `size` holding copies of `inputs` (name on the disk: source),
    with all but `leave` bytes of the rest taken by a filler file (leave=0: no filler, `size` is the disk)."""
    unshare = shutil.which("unshare")
    if unshare is None:
        pytest.skip("no unshare(1) to mount a small tmpfs without root")
    disk = tmp_path / DISK
    disk.mkdir()
    namespace = [unshare, "--user", "--map-root-user", "--mount", "sh", "-ec"]
    probe = subprocess.run([*namespace, f"mount -t tmpfs -o size=64k tmpfs {shlex.quote(str(disk))}"],
                           capture_output=True, text=True)
    if probe.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs in a user namespace here: {probe.stderr.strip()}")
    left, before = tmp_path / "left", tmp_path / "before"
    q = {name: shlex.quote(str(path)) for name, path in
         {"disk": disk, "left": left, "before": before, "out": tmp_path / "out", "err": tmp_path / "err",
          "rc": tmp_path / "rc"}.items()}
    copies = "".join(f"cp -r {shlex.quote(str(src))} {q['disk']}/{shlex.quote(name)}; "
                     for name, src in (inputs or {}).items())
    fill = (f"avail=$(df -B1 --output=avail {q['disk']} | tail -1); "
            f"head -c $((avail - {leave})) /dev/zero > {q['disk']}/.filler; " if leave else "")
    script = (f"mount -t tmpfs -o size={size} tmpfs {q['disk']}; {copies}cp -r {q['disk']} {q['before']}; {fill}"
              f"cd {q['disk']}; set +e; {shlex.join(TOOL + args)} > {q['out']} 2> {q['err']}; echo $? > {q['rc']}; "
              f"set -e; rm -f {q['disk']}/.filler; cp -r {q['disk']} {q['left']}")
    # Inside the namespace the user is root to Mesa, which then caches shaders under root's home and,
    # unable to, says so on stderr: a cache of the test's own keeps stderr the tool's.
    cache = tmp_path / "cache"
    cache.mkdir()
    subprocess.run([*namespace, script], check=True, timeout=300, env={**os.environ, "XDG_CACHE_HOME": str(cache)})
    return Run(int((tmp_path / "rc").read_text()), (tmp_path / "out").read_text(), (tmp_path / "err").read_text(),
               _hashes(before), _hashes(left), left)


def collect_args(out: str, env: str = "Reach-v2", *extra: str) -> list[str]:
    return ["collect", "--env", env, "--device", "expert", "--episodes", "3", "--render", "none", "--out", out,
            *extra]


def run_tool(args: list[str], cwd: pathlib.Path) -> None:
    done = subprocess.run(TOOL + args, cwd=cwd, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr


@pytest.fixture(scope="module")
def made(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    """`reach/` and `more/` (collectors' 3 Reach-v2 expert demos each), `merged.hdf5` (the two, merged)
    and `pick/` (3 PickPlace-v2 expert demos, a source for generate)."""
    root = tmp_path_factory.mktemp("full_disk")
    run_tool(collect_args("reach"), root)
    run_tool([*collect_args("more"), "--seed", "10"], root)
    run_tool(["merge", "reach", "more", "--out", "merged.hdf5"], root)
    run_tool(collect_args("pick", "PickPlace-v2"), root)
    return root


def collector_error(run: Run) -> tuple[str, int]:
    """A collector stopped by the full disk (exit 1, its documented status after a save failed): the
    summary and one error line on stdout, no traceback. Returns the error and the demos the summary
    counts (saved this session and in the directory, which were empty)."""
    assert "Traceback" not in run.stdout + run.stderr, run.stderr
    assert run.rc == 1, (run.stdout, run.stderr)
    errors = [line for line in run.stdout.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and errors[0] == run.stdout.strip().splitlines()[-1], run.stdout
    counted = re.search(r"(\d+) saved this session \((\d+) in ", run.stdout)
    assert counted is not None and counted[1] == counted[2], run.stdout
    return errors[0], int(counted[1])


def check_saved(error: str, out: pathlib.Path, counted: int | None = None) -> list[str]:
    """What a full disk left in the collector's directory `out`: as many demos as `counted` (the
    summary's), none that the error says it could not save, each valid (its images may be missing, to
    be added by the next session), no temporary file. Returns the demo names."""
    assert "the disk is full" in error, error
    with open_dataset(out) as ds:
        names = ds.demo_names
        problems = validate(ds)
    assert all("images are not rendered yet" in p for p in problems), problems
    assert counted is None or counted == len(names), (counted, names)
    # The bug: "could not save demo_0" while demo_0 was saved (its images were not).
    assert not [n for n in names if f"could not save {n} " in error], (names, error)
    assert re.search(r"could not (save demo_\d+|add demo_\d+'s images)", error), error
    assert not [p for p in out.rglob("*") if p.name.endswith(".tmp")]
    return names


def test_collect_on_a_full_disk_counts_what_is_saved_and_names_the_demo_that_is_not(
        tmp_path: pathlib.Path, made: pathlib.Path) -> None:
    demo = (made / "reach" / "episodes" / "demo_0.hdf5").stat().st_size
    index = (made / "reach" / "demos.hdf5").stat().st_size
    # Room for the index twice (it is rewritten beside) and a demo and a half: demo_1 does not fit.
    run = on_full_disk(tmp_path, collect_args("out"), leave=0, size=f"{2 * index + 3 * demo // 2}")
    error, counted = collector_error(run)
    assert check_saved(error, run.left / "out", counted) == ["demo_0"] and "could not save demo_1 " in error


def test_collect_with_cameras_on_a_full_disk_names_the_demo_it_did_not_save(
        tmp_path: pathlib.Path, made: pathlib.Path) -> None:
    """A demo is saved first without its images, which then replace it: the disk filling there
    left demo_0 saved (and counted), and the error said "could not save demo_0"."""
    demo = (made / "reach" / "episodes" / "demo_0.hdf5").stat().st_size
    index = (made / "reach" / "demos.hdf5").stat().st_size
    # demo_0 and its index fit; demo_0 with its images beside it does not.
    run = on_full_disk(tmp_path, collect_args("out", "Reach-v2", "--cameras", "front", "--image-size", "32"),
                       leave=0, size=f"{2 * index + 2 * demo}")
    error, counted = collector_error(run)
    assert check_saved(error, run.left / "out", counted) == ["demo_0"], error
    assert "demo_0 is saved without its images" in error, error


def test_generate_on_a_full_disk_counts_what_is_saved(tmp_path: pathlib.Path, made: pathlib.Path) -> None:
    demo = (made / "pick" / "episodes" / "demo_0.hdf5").stat().st_size
    index = (made / "pick" / "demos.hdf5").stat().st_size
    run = on_full_disk(tmp_path, ["generate", "--source", "pick", "--out", "out", "--demos", "5", "--workers", "1"],
                       inputs={"pick": made / "pick"}, leave=2 * index + 3 * demo // 2)
    run.inputs_untouched(new=frozenset(p for p in run.after if p.startswith("out/")))
    assert check_saved(run.one_line_error(), run.left / "out") == ["demo_0"]


def test_merge_on_a_full_disk(tmp_path: pathlib.Path, made: pathlib.Path) -> None:
    run = on_full_disk(tmp_path, ["merge", "reach", "more", "--out", "all.hdf5"],
                       inputs={"reach": made / "reach", "more": made / "more"})
    run.one_line_error()
    run.inputs_untouched()


def test_split_of_a_merged_file_on_a_full_disk_leaves_it_as_it_was(tmp_path: pathlib.Path,
                                                                   made: pathlib.Path) -> None:
    run = on_full_disk(tmp_path, ["split", "merged.hdf5", "--valid", "0.5"],
                       inputs={"merged.hdf5": made / "merged.hdf5"})
    run.one_line_error()
    run.inputs_untouched(new=frozenset({".merged.hdf5.lock"}))


@pytest.mark.parametrize("dataset", ["reach", "merged.hdf5"])
def test_render_obs_on_a_full_disk_leaves_the_dataset_as_it_was(tmp_path: pathlib.Path, made: pathlib.Path,
                                                                dataset: str) -> None:
    run = on_full_disk(tmp_path, ["render-obs", dataset, "--camera", "front", "--size", "32", "--workers", "1"],
                       inputs={dataset: made / dataset})
    run.one_line_error()
    run.inputs_untouched(new=frozenset({".merged.hdf5.lock"}))


def test_npz_export_on_a_full_disk(tmp_path: pathlib.Path, made: pathlib.Path) -> None:
    run = on_full_disk(tmp_path, ["export", "reach", "--to", "npz", "--out", "npz"], inputs={"reach": made / "reach"})
    run.one_line_error()
    run.inputs_untouched()


def test_lerobot_export_on_a_full_disk(tmp_path: pathlib.Path, made: pathlib.Path) -> None:
    pytest.importorskip("av")
    run = on_full_disk(tmp_path, ["export", "reach", "--to", "lerobot", "--repo-id", "me/reach", "--out", "lerobot",
                                  "--cameras", "front", "--image-size", "32"], inputs={"reach": made / "reach"})
    run.one_line_error()
    run.inputs_untouched()


def test_a_failed_save_publishes_the_demos_saved_before_it(tmp_path: pathlib.Path) -> None:
    """With the index rewritten in batches, demos saved but not yet listed when the disk fills are listed
    before the writer stops: counted, and the error names the first demo that is not saved."""
    import errno
    from typing import Any, cast

    from fetch.dataset.background import BackgroundWriter
    from fetch.errors import DatasetError

    class Batching(BackgroundWriter):
        def _publish_due(self, unpublished: int) -> bool:
            return False

        def _save(self, name: str, demo: Any) -> None:
            if name == "demo_2":
                raise OSError(errno.ENOSPC, "No space left on device")

        def _publish(self, names: list[str]) -> None:
            published.extend(names)

    published: list[str] = []
    writer = Batching(tmp_path, on_saved=None)
    writer._start()
    for _ in range(4):
        writer.commit(cast(Any, object()))  # a stand-in: this writer saves nothing
    with pytest.raises(DatasetError, match=r"could not save demo_2 in .*: the disk is full") as caught:
        writer.close()
    assert "demo_0" not in str(caught.value) and "demo_1" not in str(caught.value)
    assert published == ["demo_0", "demo_1"] and writer.saved == 2
