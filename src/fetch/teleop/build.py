"""From a `CollectRequest` to a collection session (config, whose defaults `teleop.config` decides; env,
device, window), and `collect`, which runs it: what `gym-fetch collect` calls."""

from __future__ import annotations

import dataclasses
import pathlib
import sys

from fetch._gl import has_display
from fetch.errors import FetchError, UnknownNameError
from fetch.teleop.devices import FRAMES, Device, DeviceContext, DeviceKind, options_in
from fetch.teleop.registry import device_kind
from fetch.teleop.session import CollectConfig, Display, Session, make_env


@dataclasses.dataclass(frozen=True)
class CollectRequest:
    """A collection session as `gym-fetch collect` asks for it: its settings, which way a person's input
    steers (`FRAMES`), and the devices' own options (`DeviceKind.options`; a kind's left out keeps its
    defaults)."""

    config: CollectConfig
    frame: str = "camera"
    devices: tuple[object, ...] = ()

    def __post_init__(self) -> None:
        if self.frame not in FRAMES:
            raise UnknownNameError("frame", self.frame, FRAMES)

    def through(self, kind: DeviceKind) -> DeviceKind | None:
        """The device a person drives `kind` through (its `legend_from` option), if any."""
        if not kind.legend_from or kind.options is None:
            return None
        return device_kind(getattr(options_in(self.devices, kind.options), kind.legend_from))

    def context(self, env: object, viewer: Display | None) -> DeviceContext:
        """What the device is built with, in the session's `env` and window."""
        yaw = getattr(viewer, "yaw", None) if self.frame == "camera" else None
        return DeviceContext(env=env, viewer=viewer, yaw=yaw, seed=self.config.seed,
                             max_steps=self.config.attempt_steps, keep_failures=self.config.keep_failures,
                             options=self.devices)


def wants_window(config: CollectConfig) -> bool:
    if config.render == "human":
        return True
    return config.render == "auto" and has_display() and config.human


NO_WINDOW = ("{what} reads keys typed into the collection window, and there is no display to open it on. What works: "
             "a desktop session (or ssh -X); a virtual display, for keys sent by a program (xvfb-run -a gym-fetch "
             "collect ...); or a device that needs no window: --device expert (the task's scripted expert), "
             "--device scripted (events from --scripted-json) or --device gamepad (a pad; --render none)")


def check_window(request: CollectRequest) -> None:
    """FetchError, before anything opens, when what a person drives with reads the window (the keyboard) and
    no window will open: one message saying what works."""
    from fetch.teleop.viewer import window_possible

    config = request.config
    kind = device_kind(config.device)
    flag = f"--device {kind.name}"
    person = request.through(kind)
    if person is not None:  # a person drives through another device (takeover): that one may read the window
        flag = f"--{kind.legend_from.replace('_', '-')} {person.name}"
        kind = person
    if not kind.reads_window:
        return
    if not window_possible():
        raise FetchError(NO_WINDOW.format(what=flag))
    if not wants_window(config):
        raise FetchError(f"{flag} reads keys typed into the collection window, which --render {config.render} does "
                         "not open: leave --render out (auto opens it on a display) or use --render human")


def make_device(request: CollectRequest, env: object, viewer: Display | None) -> Device:
    return device_kind(request.config.device).build(request.context(env, viewer))


def session_from_request(request: CollectRequest) -> Session:
    config = request.config
    check_window(request)
    env = make_env(config)
    viewer: Display | None = None
    if wants_window(config):
        from fetch.teleop.viewer import Viewer

        kind = device_kind(config.device)
        person = request.through(kind)
        viewer = Viewer(env, kind.legend + (person.legend if person is not None else ()))
    try:
        device = make_device(request, env, viewer)
    except BaseException:
        if viewer is not None:
            viewer.close()
        raise
    print(f"collecting {config.env_id} with {config.device} into {config.out} "
          f"({'until you quit' if not config.episodes else f'{config.episodes} demos'})", file=sys.stderr)
    try:
        return Session(config, device, env=env, display=viewer)
    except BaseException:  # refused (a task with no tight start): what was opened for it is closed
        device.close()
        if viewer is not None:
            viewer.close()
        raise


def collect(request: CollectRequest) -> int:
    """Run the collection session `request` asks for; print its summary and, when demos were saved, what to do
    with them next; the exit status."""
    session = session_from_request(request)
    summary = session.run()
    print(summary.describe(), flush=True)
    if summary.exit_status == 0 and summary.total_saved:
        print(next_steps(request.config.out, request.config.format), flush=True)
    return summary.exit_status


def next_steps(out: str, dataset_format: str) -> str:
    """What to do with demos just collected into `out`: look at them, and learn from them."""
    if dataset_format != "hdf5":  # the npz files: what reads them
        return f"next: check them with `gym-fetch info {out}` and `gym-fetch replay {out} --check`"
    name = pathlib.PurePath(out).name or "demos"
    return (f"next: watch them with `gym-fetch view {out} --out report/{name}/`; train a policy on them with "
            f"`gym-fetch train {out} --out runs/{name}` (or first make many more from them: `gym-fetch generate`)")
