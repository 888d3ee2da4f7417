"""Every kind of collection device, in one list: the CLI, the session and the viewer read only this.

A new device is one module that declares a `DeviceKind` (see `fetch.teleop.devices`) plus one entry here.
"""

from __future__ import annotations

from fetch.errors import UnknownNameError
from fetch.teleop import expert, keyboard, policy, scripted
from fetch.teleop.devices import DeviceKind
from fetch.teleop.gamepad import backend as gamepad

KINDS: tuple[DeviceKind, ...] = (gamepad.KIND, keyboard.KIND, scripted.KIND, expert.KIND, policy.KIND)

_BY_NAME: dict[str, DeviceKind] = {}
for _kind in KINDS:
    for _name in (_kind.name, *_kind.aliases):
        if _name in _BY_NAME:
            raise ValueError(f"two devices are called {_name!r}")
        _BY_NAME[_name] = _kind

DEVICE_NAMES: tuple[str, ...] = tuple(_BY_NAME)
"""Valid `--device` values, aliases included."""


def device_kind(name: str) -> DeviceKind:
    """The device called `name` (or one of its aliases); UnknownNameError listing the valid ones."""
    try:
        return _BY_NAME[name]
    except KeyError:
        raise UnknownNameError("device", name, DEVICE_NAMES) from None
