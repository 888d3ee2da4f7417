"""The device registry: every device declared once, read by the CLI, the session and the viewer."""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import sys
import textwrap
from pathlib import Path

import pytest

import fetch.learn.device  # noqa: F401  (registers --device policy)
from fetch.cli import _parser as build_parser
from fetch.errors import UnknownNameError
from fetch.teleop.devices import DeviceKind
from fetch.teleop.registry import DEVICE_NAMES, KINDS, device_kind
from fetch.teleop.session import CollectConfig


def _kind(**changes: object) -> DeviceKind:
    fields: dict[str, object] = dict(name="spacemouse", human=True, legend=("puck: move",), summary="a 3-D mouse",
                                     add_arguments=None, build=lambda context: None)
    fields.update(changes)
    return DeviceKind(**fields)  # type: ignore[arg-type]


def test_a_complete_declaration_is_accepted() -> None:
    assert _kind().name == "spacemouse"


@pytest.mark.parametrize("changes, problem", [
    ({"legend": ()}, "needs a legend"),
    ({"human": "yes"}, "human must be True or False"),
    ({"legend": ["a list"]}, "legend must be a tuple"),
    ({"summary": ""}, "summary"),
    ({"build": "not a function"}, "build must be a function"),
    ({"add_arguments": 3}, "add_arguments"),
    ({"name": "space mouse"}, "name must be a word"),
    ({"add_arguments": lambda p: None}, "go together"),
    ({"options": dict}, "options must be a dataclass"),
    ({"legend_from": "takeover_with"}, "legend_from must name a field"),
])
def test_a_bad_declaration_fails_when_it_is_made(changes: dict[str, object], problem: str) -> None:
    with pytest.raises(TypeError, match=problem):
        _kind(**changes)


def test_a_device_module_missing_a_field_fails_at_import(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A new device module that forgets its legend (or any field) cannot even be imported."""
    (tmp_path / "forgetful_device.py").write_text(textwrap.dedent("""
        from fetch.teleop.devices import DeviceKind
        KIND = DeviceKind(name="forgetful", human=True, summary="a device with no legend",
                          add_arguments=None, build=lambda context: None)
    """))
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(TypeError, match="legend"):
        importlib.import_module("forgetful_device")
    sys.modules.pop("forgetful_device", None)


def test_the_cli_offers_exactly_the_registered_devices_and_their_flags() -> None:
    parser = build_parser()
    collect = next(a for a in parser._subparsers._group_actions  # type: ignore[union-attr]
                   if isinstance(a, argparse._SubParsersAction)).choices["collect"]
    device = next(a for a in collect._actions if a.dest == "device")
    assert list(device.choices) == DEVICE_NAMES  # type: ignore[arg-type]
    assert "policy" in DEVICE_NAMES  # registered by fetch.learn.device, a layer above
    dests = {a.dest for a in collect._actions}
    assert {"policy", "scripted_json", "profile", "frame"} <= dests  # each device's own flags


def test_every_device_option_is_a_collect_flag() -> None:
    """A device reads its flags as typed options, one field per flag: each field is a flag `collect` declares."""
    parser = build_parser()
    collect = next(a for a in parser._subparsers._group_actions  # type: ignore[union-attr]
                   if isinstance(a, argparse._SubParsersAction)).choices["collect"]
    dests = {a.dest for a in collect._actions}
    for kind in KINDS:
        if kind.options is not None:
            fields = {f.name for f in dataclasses.fields(kind.options)}
            assert fields <= dests, f"{kind.name}: {sorted(fields - dests)} are no collect flags"


def test_a_device_gets_its_options_or_their_defaults() -> None:
    from fetch.teleop.devices import DeviceContext
    from fetch.teleop.expert import EXPERT_NOISE, ExpertOptions
    from fetch.teleop.scripted import ScriptedOptions

    context = DeviceContext(env=None, viewer=None, yaw=None, options=(ScriptedOptions("events.json"),))
    assert context.options_for(ScriptedOptions).scripted_json == "events.json"
    assert context.options_for(ExpertOptions) == ExpertOptions(EXPERT_NOISE, None)


@pytest.mark.parametrize("kind", KINDS, ids=lambda k: k.name)
def test_the_session_reads_pacing_from_the_declaration(kind: DeviceKind) -> None:
    config = CollectConfig(env_id="Reach-v2", device=kind.name)
    assert config.human is kind.human
    assert config.rate(0.04) == (25.0 if kind.human else 0.0)


def test_an_alias_is_stored_by_the_device_s_name() -> None:
    assert CollectConfig(env_id="Reach-v2", device="xbox").device == "gamepad"
    assert device_kind("xbox") is device_kind("gamepad")


def test_an_unknown_device_names_the_valid_ones() -> None:
    with pytest.raises(UnknownNameError, match="unknown device 'spacemouse'; known: gamepad, xbox, keyboard"):
        CollectConfig(env_id="Reach-v2", device="spacemouse")


def test_a_python_config_decides_what_collect_decides(tmp_path: Path) -> None:
    """CollectConfig's open settings are decided in one place, for `gym-fetch collect` and Python alike: by
    the device for a new dataset, by the dataset's own settings for one that exists."""
    from fetch.cli import main
    from fetch.dataset import open_dataset

    expert = CollectConfig(env_id="Reach-v2", device="expert", out=str(tmp_path / "new"))
    assert (expert.stop_on_success, expert.max_steps) == (False, 50)  # to the registered horizon
    person = CollectConfig(env_id="Reach-v2", device="keyboard", out=str(tmp_path / "new"))
    assert (person.stop_on_success, person.max_steps) == (True, 500)
    told = CollectConfig(env_id="Reach-v2", device="expert", out=str(tmp_path / "new"), max_steps=70)
    assert (told.stop_on_success, told.max_steps) == (False, 70)
    out = tmp_path / "demos"
    assert main(["collect", "--env", "Reach-v2", "--device", "expert", "--episodes", "1", "--render", "none",
                 "--out", str(out), "--stop-on-success", "--max-steps", "60"]) == 0
    with open_dataset(out) as ds:
        recorded = dict(ds.settings)
    adding = CollectConfig(env_id="Reach-v2", device="expert", out=str(out))
    assert (recorded["stop_on_success"], recorded["max_steps"]) == (True, 60)
    assert (adding.stop_on_success, adding.max_steps) == (True, 60)
