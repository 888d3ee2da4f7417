"""What a newcomer trips on, round two: install commands that work from a clone as written, and one-line
answers to wrong turns."""

from __future__ import annotations

import importlib.metadata
import pathlib
import re

from fetch.cli import main

ROOT = pathlib.Path(__file__).resolve().parent.parent


def extras() -> set[str]:
    return set(importlib.metadata.metadata("gym-fetch-v2").get_all("Provides-Extra") or ())


def test_every_install_command_names_the_source_tree_and_a_real_extra() -> None:
    """gym-fetch-v2 is not on PyPI: `pip install "gym-fetch-v2[train]"` fails from a clone ("No matching
    distribution"). Every command the README, the docs and the errors give installs from the source tree."""
    import fetch.dataset.exports.export
    import fetch.dataset.exports.lerobot
    import fetch.learn
    from fetch.errors import install_hint

    texts = {p.name: p.read_text() for p in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]}
    texts.update({"TORCH_INSTALL": fetch.learn.TORCH_INSTALL,
                  "MINARI_INSTALL": fetch.dataset.exports.export.MINARI_INSTALL,
                  "lerobot INSTALL": fetch.dataset.exports.lerobot.INSTALL, "install_hint": install_hint("video")})
    known = extras()
    seen = 0
    for where, text in texts.items():
        assert "gym-fetch-v2[" not in text, f"{where} installs from PyPI, where the package is not"
        for names in re.findall(r'pip install [^\n`]*?"\.\[([a-z,]+)\]"', text):
            assert set(names.split(",")) <= known, (where, names)
            seen += 1
    assert seen >= 8


def test_the_readme_says_how_to_get_torchs_cpu_wheels() -> None:
    readme = (ROOT / "README.md").read_text()
    assert "pip install torch --index-url https://download.pytorch.org/whl/cpu" in readme


def test_a_misspelt_camera_lists_the_cameras_to_choose_from(tmp_path: pathlib.Path, capsys) -> None:  # noqa: ANN001
    """Not the robot model's internal ones (head_camera_rgb, gripper_camera_rgb, lidar, ...)."""
    out = tmp_path / "demos"
    assert main(["collect", "--env", "Reach-v2", "--device", "expert", "--episodes", "1", "--render", "none",
                 "--out", str(out)]) == 0
    capsys.readouterr()
    assert main(["replay", str(out), "--video", str(tmp_path / "v.mp4"), "--camera", "frnt"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith("unknown camera 'frnt'; known: front, side, behind, wrist"), err
