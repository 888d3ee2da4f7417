"""The command line as a newcomer meets it: help for every flag, the seed's script under its own
name, and the seed's npz files readable by `info` and `replay`."""

from __future__ import annotations

import argparse
import pathlib
import subprocess
import sys

import numpy as np
import pytest

from fetch.cli import _parser, main

ROOT = pathlib.Path(__file__).resolve().parent.parent


def _subcommands() -> dict[str, argparse.ArgumentParser]:
    parser = _parser()
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def test_every_flag_has_help_with_its_default() -> None:
    missing, no_default = [], []
    for name, sub in _subcommands().items():
        for action in sub._actions:
            if isinstance(action, argparse._HelpAction) or not action.option_strings:
                continue
            flag = f"{name} {action.option_strings[0]}"
            if not action.help:
                missing.append(flag)
            elif (action.nargs != 0 and action.default is not None and action.default != argparse.SUPPRESS
                  and "default" not in action.help and str(action.default) not in action.help):
                no_default.append(flag)
    assert missing == [] and no_default == [], {"no help": missing, "help without the default": no_default}


def test_every_positional_argument_has_help() -> None:
    missing = [f"{name} {action.dest}" for name, sub in _subcommands().items() for action in sub._actions
               if not action.option_strings and not action.help]
    assert missing == []


def test_version_names_the_package_and_mujoco(capsys: pytest.CaptureFixture[str]) -> None:
    import mujoco

    import fetch

    with pytest.raises(SystemExit) as stop:
        main(["--version"])
    assert stop.value.code == 0
    assert capsys.readouterr().out.strip() == (f"gym-fetch-v2 {fetch.__version__} (mujoco {mujoco.__version__}, "
                                               f"python {sys.version.split()[0]})")


def test_the_seeds_script_names_itself_in_its_usage() -> None:
    out = subprocess.run([sys.executable, str(ROOT / "collect_fetch_demo.py"), "--help"], capture_output=True,
                         text=True, check=True).stdout
    assert out.startswith("usage: collect_fetch_demo.py ")


def test_the_seeds_script_reports_errors_under_its_name(tmp_path: pathlib.Path) -> None:
    result = subprocess.run([sys.executable, str(ROOT / "collect_fetch_demo.py"), "--env", "Nope-v2", "--device",
                             "expert", "--render", "none", "--out", str(tmp_path / "d")],
                            capture_output=True, text=True)
    assert result.returncode == 2
    assert result.stderr.startswith("collect_fetch_demo.py: error:"), result.stderr


@pytest.fixture(scope="module")
def npz_dir(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    out = tmp_path_factory.mktemp("npz") / "reach"
    assert main(["collect", "--env", "Reach-v2", "--device", "expert", "--episodes", "2", "--render", "none",
                 "--format", "npz", "--out", str(out)]) == 0
    return out


def test_info_summarises_npz_files(npz_dir: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["info", str(npz_dir)]) == 0
    out = capsys.readouterr().out
    assert "npz" in out and "Reach-v2" in out and "2 (2 successful)" in out and out.rstrip().endswith("valid")


def test_replay_checks_npz_files_bit_for_bit(npz_dir: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["replay", str(npz_dir), "--check"]) == 0
    assert "2 exact, 0 deviating" in capsys.readouterr().out


def test_replay_and_info_catch_a_changed_npz_file(npz_dir: pathlib.Path, tmp_path: pathlib.Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    copy = tmp_path / "copy"
    copy.mkdir()
    first = sorted(npz_dir.glob("*.npz"))[0]
    with np.load(first) as f:
        arrays = {k: f[k] for k in f.files}
    arrays["states"] = arrays["states"].copy()
    arrays["states"][3, 0] += 1e-9
    np.savez(copy / first.name, **arrays)
    assert main(["replay", str(copy), "--check"]) == 1
    assert "DEVIATES" in capsys.readouterr().out
    arrays["action"] = arrays["action"].copy()
    arrays["action"][0, 0] = np.nan
    np.savez(copy / first.name, **arrays)
    assert main(["info", str(copy)]) == 1
    assert "NaN" in capsys.readouterr().out


def test_verbose_replay_of_an_exact_demo_reports_no_deviation(npz_dir: pathlib.Path,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["replay", str(npz_dir), "--check", "--verbose"]) == 0
    lines = [line for line in capsys.readouterr().out.splitlines() if line.startswith("Reach-v2_ep")]
    assert len(lines) == 2 and all(line.endswith("steps, exact") for line in lines), lines
