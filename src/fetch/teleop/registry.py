"""Every kind of collection device, in one list: the CLI, the session and the viewer read only this.

A new device is one module that declares a `DeviceKind` (see `fetch.teleop.devices`) plus one entry here;
a device from a layer above (the trained policy, `fetch.learn.device`) registers itself with `register`
when its module is imported, so this layer never imports it.
"""

from __future__ import annotations

from fetch.errors import UnknownNameError
from fetch.teleop import expert, keyboard, scripted
from fetch.teleop.devices import DeviceKind
from fetch.teleop.gamepad import backend as gamepad

KINDS: list[DeviceKind] = []
"""Every device kind, in the order `--help` lists them."""
_BY_NAME: dict[str, DeviceKind] = {}
DEVICE_NAMES: list[str] = []
"""Valid `--device` values, aliases included."""


def register(kind: DeviceKind) -> DeviceKind:
    """Add a device kind (its name and aliases must be new); returns it."""
    names = (kind.name, *kind.aliases)
    for name in names:
        if name in _BY_NAME:
            raise ValueError(f"two devices are called {name!r}")
    KINDS.append(kind)
    for name in names:
        _BY_NAME[name] = kind
        DEVICE_NAMES.append(name)
    return kind


for _kind in (gamepad.KIND, keyboard.KIND, scripted.KIND, expert.KIND):
    register(_kind)


def device_kind(name: str) -> DeviceKind:
    """The device called `name` (or one of its aliases); UnknownNameError listing the valid ones."""
    try:
        return _BY_NAME[name]
    except KeyError:
        raise UnknownNameError("device", name, DEVICE_NAMES) from None
