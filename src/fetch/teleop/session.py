"""The collection loop: attempts at a fixed control rate, success held, successful attempts saved."""

from __future__ import annotations

import dataclasses
import signal
import time
from collections.abc import Callable
from typing import Any, Protocol, cast

import gymnasium as gym
import numpy as np

from fetch._progress import say
from fetch.dataset.background import MAX_QUEUED
from fetch.dataset.episode import Demo, EpisodeBuffer
from fetch.dataset.formats import open_writer, recorded_layout
from fetch.errors import FetchError
from fetch.generate.room import NO_TIGHT_START, resets_tight
from fetch.rendering import check_camera
from fetch.stopping import Stopped, acting_on_stop, polled, raise_if_stopped, signals_held
from fetch.tasks.subtasks import Scene
from fetch.teleop.config import CollectConfig
from fetch.teleop.devices import Command, Device
from fetch.teleop.registry import device_kind
from fetch.timing import Clock


@dataclasses.dataclass
class HudState:
    """What the heads-up display shows."""

    env_id: str
    attempt: int
    saved: int
    target: int
    step: int
    max_steps: int
    success: bool
    held: int
    hold_needed: int
    gripper_closed: bool
    precision: bool = False
    status: str = ""
    waiting: bool = False
    """The attempt's clock has not started: nothing moves until the person's first input."""
    dt: float = 0.04
    """[s] one step, to show the time left."""
    rewound: int = 0
    """Steps taken back in this attempt."""

    @property
    def seconds_left(self) -> float:
        return max(self.max_steps - self.step, 0) * self.dt


class Display(Protocol):
    """A window that shows the scene and the HUD once per tick (the viewer; None when headless)."""

    def show(self, hud: HudState) -> None:
        """Read the window's input and show the newest picture of the scene with the HUD; never waits for a
        frame to be drawn (the control loop calls it every tick)."""

    def next_camera(self) -> None: ...

    def close(self) -> None: ...


@dataclasses.dataclass
class Attempt:
    """How one attempt went."""

    number: int
    seed: int
    steps: int
    success: bool
    ended_by: str  # "success", "finish", "discard", "time limit", "terminated", "quit"
    saved_as: str | None
    achieved_hz: float
    rewound: int = 0
    """Steps the person took back (`Command.rewind`): not in the saved demo."""


@dataclasses.dataclass
class SessionSummary:
    attempts: list[Attempt]
    saved: int
    total_saved: int
    out: str
    achieved_hz: float
    late_ticks: int
    error: str | None = None
    stopped_by: int | None = None
    """the signal that stopped the session (SIGINT, SIGTERM), if one did."""
    most_behind: int = 0
    """the most demos that waited to be saved at once (at most MAX_QUEUED)."""

    @property
    def exit_status(self) -> int:
        """0; 1 after an error; 128 + the signal's number after a stop signal (130 for Ctrl-C)."""
        if self.error:
            return 1
        return 128 + self.stopped_by if self.stopped_by is not None else 0

    @property
    def success_rate(self) -> float:
        return sum(a.success for a in self.attempts) / len(self.attempts) if self.attempts else 0.0

    def describe(self) -> str:
        n = len(self.attempts)
        rate = f"{self.achieved_hz:.1f} Hz" if self.achieved_hz else "n/a"
        text = (f"{n} attempts, {self.saved} saved this session ({self.total_saved} in {self.out}), "
                f"success rate {100 * self.success_rate:.0f}%, achieved control rate {rate}")
        if self.most_behind > 1:
            text += f"; saving fell up to {self.most_behind} demos behind"
        return text + (f"\nerror: {self.error}" if self.error else "")


def make_env(config: CollectConfig) -> gym.Env:
    """The env of a session: its TimeLimit is --max-steps."""
    return gym.make(config.env_id, max_episode_steps=config.max_steps, reward_type=config.reward_type)


class Session:
    """Runs attempts with one device until the target is reached or the operator quits."""

    def __init__(self, config: CollectConfig, device: Device, env: gym.Env | None = None,
                 display: Display | None = None, log: Callable[[str], None] | None = None) -> None:
        self.config = config
        self.env = env if env is not None else make_env(config)
        self.base = cast(Any, self.env.unwrapped)  # a FetchEnv
        self.device = device
        self.display = display
        self.log = log or say
        for camera in config.cameras:
            check_camera(self.base.model, camera)
        self._tight_seeds: list[int] = []  # with --starts tight: the seeds from config.seed on that start tight
        if config.starts == "tight":
            self.seed_of(0)  # a task with no tight start is refused before its dataset folder is made
        self.committed = 0
        """demos handed to the writer this session (what the episode count is judged by)"""
        self.saved_this_session = 0
        """demos the writer reported on disk (listed in an index that is on disk): what the summary says"""
        self.writer = open_writer(config.format, config.out, self.env, settings=config.settings(),
                                  device=config.device, cameras=config.cameras, image_size=config.image_size,
                                  image_quality=config.image_quality, on_saved=self._on_saved)
        if getattr(self.writer, "recovered", 0):
            self.log(f"recovered {self.writer.recovered} demo(s) written just before an interruption")
        # The loop records states only: the writer renders `--cameras` images from them in another
        # process once the demo is saved, so images cost the control loop nothing.
        self.buffer = EpisodeBuffer(recorded_layout(self.env),
                                    capacity=min(config.attempt_steps, 1024))
        self.clock = Clock(config.rate(self.base.dt))
        self.attempts: list[Attempt] = []
        self._gripper_closed = False
        self.ticks: list[tuple[float, float, float]] = []
        """Per step: its deadline, when the device was polled, when the step returned [s, perf_counter]."""

    def _on_saved(self, name: str, demo: Demo) -> None:
        self.saved_this_session += 1  # only the writer's thread calls this
        self.log(f"saved {name}: {demo.num_samples} steps, seed {demo.attrs['seed']}"
                 f"{'' if demo.success else ' (failed, kept)'}")

    def run(self) -> SessionSummary:
        error, stopped_by = None, None
        with polled():  # a stop signal lands at the next tick, and not while the saves are finished
            try:
                self._collect()
            except KeyboardInterrupt as e:
                acting_on_stop()
                stopped_by = e.signum if isinstance(e, Stopped) else int(signal.SIGINT)
                self.log(f"interrupted ({signal.Signals(stopped_by).name}): finishing the saves")
            except FetchError as e:  # the writer or the viewer failed: stop collecting, keep what is saved
                error = str(e)
            finally:
                with signals_held("still finishing the saves; they will complete, then the session stops"):
                    try:
                        self.writer.close()
                    except FetchError as e:
                        error = error or str(e)
                    self.device.close()
                    if self.display is not None:
                        self.display.close()
        rates = [a.achieved_hz for a in self.attempts if a.achieved_hz > 0]
        return SessionSummary(self.attempts, self.saved_this_session, self.writer.saved, self.config.out,
                              float(np.mean(rates)) if rates else 0.0, self.clock.late, error, stopped_by,
                              self.writer.most_behind)

    def _collect(self) -> None:
        """Attempts until enough are saved or the operator quits."""
        while not self.config.episodes or self.committed < self.config.episodes:
            attempt = self.attempt()
            self.attempts.append(attempt)
            if self.config.verbose or attempt.saved_as is None:
                self.log(f"attempt {attempt.number} (seed {attempt.seed}): {attempt.steps} steps, ended by "
                         f"{attempt.ended_by}" + ("" if attempt.saved_as else ", not saved"))
            if attempt.ended_by == "quit":
                break

    def seed_of(self, number: int) -> int:
        """The reset seed of the dataset's attempt `number`: seed + number, or with `starts` "tight" the
        (number+1)-th seed from seed on whose start is tight (the same in a resumed session: found again by
        resetting the env, a few milliseconds each); a `FetchError` where `NO_TIGHT_START` seeds in a row are not."""
        cfg = self.config
        if cfg.starts == "all":
            return cfg.seed + number
        scene = Scene(self.base.model)
        while len(self._tight_seeds) <= number:
            first = self._tight_seeds[-1] + 1 if self._tight_seeds else cfg.seed
            for seed in range(first, first + NO_TIGHT_START):
                if resets_tight(self.env, seed, scene):
                    self._tight_seeds.append(seed)
                    break
            else:
                raise FetchError(f"none of the {NO_TIGHT_START} starts of {cfg.env_id} from seed {first} on is tight "
                                 f"(its object close beside something); use --starts all")
        return self._tight_seeds[number]

    def attempt(self) -> Attempt:
        """One episode from one reset, recorded; saved if it held success (or --keep-failures)."""
        cfg, env, buf = self.config, self.env, self.buffer
        number = self.writer.reserve_attempt()
        seed = self.seed_of(number)
        obs, info = env.reset(seed=seed)
        self.device.reset()
        buf.begin(obs, self.base.get_state())
        started = time.time()
        held = rewound = stepped = 0
        success = False
        ended_by = "time limit"
        # A person's clock starts at their first input: until then the arm holds still (as with a pad
        # unplugged), so reading the window or the legend costs no time of the attempt.
        waiting = cfg.human and device_kind(cfg.device).waits_for_input
        self.clock.restart()
        command = Command(np.zeros(4, np.float32))
        first = last = 0.0
        while True:
            self._show(number, buf.length, info, held, command, waiting, rewound)
            deadline = self.clock.wait()
            raise_if_stopped()
            polled = time.perf_counter()
            command = self.device.poll(obs)
            if command.switch_camera and self.display is not None:
                self.display.next_camera()
            if command.quit:
                ended_by = "quit"
                break
            if command.discard:
                ended_by = "discard"
                break
            if command.rewind:
                rewound += min(command.rewind, buf.length)
                obs, info = self._rewind(command.rewind)
                held = 0
                continue
            if command.paused or (waiting and not command.acts):
                continue
            waiting = False
            self._gripper_closed = command.closes_gripper
            now = time.time()
            first, last = first or now, now
            stepped += 1
            obs, reward, terminated, truncated, info = env.step(np.asarray(command.action, dtype=np.float32))
            action = self.base.last_action  # as the env clipped and applied it
            self.ticks.append((deadline, polled, time.perf_counter()))
            self.base.get_state(out=buf.state_row())
            ok = info["is_success"] >= 1.0
            buf.record(action, obs, float(reward), terminated, truncated, ok, now, command.label,
                       command.intervention, command.proposal)
            held = held + 1 if ok else 0
            success = success or held >= cfg.success_hold_steps
            if success and cfg.stop_on_success:
                ended_by = "success"
                break
            if command.finish:
                ended_by = "finish"
                break
            if truncated:
                break
            if terminated and not cfg.ignore_env_done:
                ended_by = "terminated"
                break
        t = buf.length
        # Every step taken counts towards the rate, the rewound ones too.
        achieved = (stepped - 1) / (last - first) if stepped > 1 and last > first else 0.0
        saved_as = None
        # Quitting mid-attempt keeps it only if it had already succeeded (no partial failures).
        keep = success or (cfg.keep_failures and ended_by != "quit")
        if ended_by != "discard" and keep and t > 0:
            demo = buf.demo({"seed": seed, "success": success, "env_id": cfg.env_id, "device": self.device.name,
                             "attempt": number, "control_hz": self.clock.period and 1.0 / self.clock.period,
                             "achieved_hz": achieved, "started": started, "ended": time.time()})
            if self.writer.behind >= MAX_QUEUED:
                self.log(f"saving is {self.writer.behind} demos behind; waiting for the writer")
            saved_as = self.writer.commit(demo)
            self.committed += 1
        return Attempt(number, seed, t, success, ended_by, saved_as, achieved, rewound)

    def _rewind(self, steps: int) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Take the attempt back `steps` steps (to its start at most): the env returns to the state it
        was in then, the buffer forgets the steps after it (so the saved demo is the path that was kept,
        and replays exactly), and the device's gripper toggle matches the fingers again. Returns the
        observation and info there."""
        buf = self.buffer
        self.base.set_state(buf.rewind(steps))
        last = buf.actions[buf.length - 1] if buf.length else None
        self._gripper_closed = bool(last is not None and last[3] < 0)
        gripper_from = getattr(self.device, "gripper_from", None)
        if gripper_from is not None:
            gripper_from(last)
        return cast(tuple[dict[str, np.ndarray], dict[str, Any]], self.base.observe())

    def _show(self, number: int, step: int, info: dict[str, Any], held: int, command: Command,
              waiting: bool = False, rewound: int = 0) -> None:
        if self.display is None:
            return
        self.display.show(HudState(
            env_id=self.config.env_id, attempt=number, saved=self.writer.saved, target=self.config.episodes,
            step=step, max_steps=self.config.attempt_steps, success=info.get("is_success", 0.0) >= 1.0, held=held,
            hold_needed=self.config.success_hold_steps, gripper_closed=self._gripper_closed,
            precision=command.precision,
            status=command.status or (f"saving: {self.writer.behind} queued" if self.writer.behind else ""),
            waiting=waiting, dt=self.base.dt, rewound=rewound))
