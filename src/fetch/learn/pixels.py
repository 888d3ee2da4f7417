"""The torch side of the pixel policy (`cnn-chunk`): camera images, the robot's own readings and the goal
-> chunks of actions.

Each camera has its own small convolutional encoder, trained from scratch with the rest: four 3 x 3
convolutions (three of stride 2) and a spatial soft-argmax that turns each of `KEYPOINTS` feature maps
into the image point where it is strongest (robomimic's and Levine et al.'s keypoints: where things are,
which is what reaching and grasping need, in few numbers). The keypoints of every camera and the
normalised vector input (the readings and the goal; the rest of the state is blinded to 0 before it,
`PolicySettings.blind`) go through mlp-chunk's MLP. Training shifts each image by up to `SHIFT` pixels
(DrQ's random shift: the edge pixels repeated, then a random crop back to size), so the policy does not
learn exact pixel positions of one demo's frames. Acting is mlp-chunk's (`ChunkActor`).

While training, a second head guesses from the same features what the policy does not see of the state
(the objects' positions, the drawer's opening, ..., normalised; `Samples.unseen`), and its squared error
is added to the loss (`pixel_loss`): the demos' states teach the encoder where things are far faster than
the actions alone do (on PickPlace, 8 % -> 76 % after the same 1500 steps; docs/training.md). The guess is
never used to act, and a policy acts the same whatever the state holds there (tests/test_pixels.py).
"""

from __future__ import annotations

import dataclasses
from typing import cast

import torch
import torch.nn.functional as F
from torch import nn

from fetch.learn.kinds import PolicyConfig
from fetch.learn.policies import ACTION_SIZE, Batch, ChunkActor, Kind, Members, chunk_examples, masked_loss

KEYPOINTS = 32
"""Feature maps (and so image points) per camera."""
SHIFT = 4
"""[px] the largest random shift of a training image, each way (DrQ's 4 px, at 84 x 84; the same 4 px at the
default 64 x 64, where the camera missions were measured with it)."""
CHANNELS = 32
UNSEEN_WEIGHT = 1.0
"""How much the encoder's guess of the unseen state counts in training beside the actions (0: not at all)."""


class SpatialSoftArgmax(nn.Module):
    """(N, C, H, W) feature maps -> (N, 2C): each map's expected (x, y) under its softmax, in [-1, 1]."""

    def __init__(self) -> None:
        super().__init__()
        self.log_temperature = nn.Parameter(torch.zeros(()))

    def forward(self, maps: torch.Tensor) -> torch.Tensor:
        maps = maps.float()  # where the points are, to the last bit a softmax over the map gives (also under bf16)
        n, c, h, w = maps.shape
        weights = torch.softmax(maps.reshape(n, c, h * w) / self.log_temperature.exp(), dim=-1)
        ys, xs = torch.meshgrid(torch.linspace(-1.0, 1.0, h, device=maps.device),
                                torch.linspace(-1.0, 1.0, w, device=maps.device), indexing="ij")
        grid = torch.stack([xs.reshape(-1), ys.reshape(-1)], dim=-1)  # (H*W, 2)
        return (weights @ grid).reshape(n, 2 * c)


class Encoder(nn.Module):
    """One camera's (N, 3, H, W) image in [-0.5, 0.5] -> (N, 2 * KEYPOINTS) keypoints."""

    def __init__(self) -> None:
        super().__init__()
        self.net = nn.Sequential(
            nn.Conv2d(3, CHANNELS, 3, stride=2, padding=1), nn.ReLU(),
            nn.Conv2d(CHANNELS, CHANNELS, 3, stride=2, padding=1), nn.ReLU(),
            nn.Conv2d(CHANNELS, 2 * CHANNELS, 3, stride=2, padding=1), nn.ReLU(),
            nn.Conv2d(2 * CHANNELS, 2 * CHANNELS, 3, padding=1), nn.ReLU(),
            nn.Conv2d(2 * CHANNELS, KEYPOINTS, 1),
            SpatialSoftArgmax())

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        return self.net(image)


def random_shift(images: torch.Tensor, shift: int) -> torch.Tensor:
    """(N, C, H, W) images, each moved by its own whole-pixel offset in [-shift, shift]^2 (drawn from torch's
    CPU generator, on any device), the edge pixels repeated into what is uncovered. One slice per image (a
    gather over every pixel took longer)."""
    n, c, h, w = images.shape
    padded = F.pad(images, (shift, shift, shift, shift), mode="replicate")
    dy, dx = torch.randint(0, 2 * shift + 1, (2, n)).tolist()
    return torch.stack([padded[i, :, y:y + h, x:x + w] for i, (y, x) in enumerate(zip(dy, dx, strict=True))])


class PixelChunk(nn.Module):
    """(N, D) normalised vector input and one (N, H, W, 3) uint8 image per camera -> (N, chunk, 4) actions."""

    memory_format = torch.channels_last
    """How the encoders' weights and images lie in memory: NHWC (an (N, H, W, 3) image's permuted view
    already is), on which oneDNN's convolutions train a step 1.13x as fast as on NCHW on a 2-core AVX2 CPU
    (`python -m benchmarks.pixel_step`). The same model and the same numbers up to rounding."""

    def __init__(self, config: PolicyConfig) -> None:
        super().__init__()
        self.chunk = config.chunk
        self.encoders = nn.ModuleList(Encoder() for _ in config.cameras)
        self.encoders.to(memory_format=self.memory_format)  # type: ignore[call-overload]  # (torch's stubs lack it)
        sizes = [config.obs_size + 2 * KEYPOINTS * len(config.cameras)] + [config.hidden] * config.layers
        body: list[nn.Module] = []
        for a, b in zip(sizes[:-1], sizes[1:], strict=True):
            body += [nn.Linear(a, b), nn.ReLU()]
        self.head = nn.Sequential(*body, nn.Linear(sizes[-1], config.chunk * ACTION_SIZE))
        self.unseen = nn.Sequential(nn.Linear(sizes[0], config.hidden), nn.ReLU(),
                                    nn.Linear(config.hidden, max(1, len(config.blind))))

    def features(self, x: torch.Tensor, *images: torch.Tensor) -> torch.Tensor:
        """The vector input and every camera's keypoints, side by side."""
        if len(images) != len(self.encoders):
            raise ValueError(f"the policy sees {len(self.encoders)} camera(s), given {len(images)} image batch(es)")
        features = [x]
        for encoder, image in zip(self.encoders, images, strict=True):
            pixels = image.permute(0, 3, 1, 2).float() / 255.0 - 0.5
            if self.training and SHIFT:
                pixels = random_shift(pixels, SHIFT).contiguous(memory_format=self.memory_format)
            features.append(encoder(pixels))
        return torch.cat(features, dim=-1)

    def forward(self, x: torch.Tensor, *images: torch.Tensor) -> torch.Tensor:
        return self.head(self.features(x, *images)).reshape(len(x), self.chunk, ACTION_SIZE)

    def forward_both(self, x: torch.Tensor, *images: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The actions, and the guess of what the policy does not see of the state."""
        features = self.features(x, *images)
        return self.head(features).reshape(len(x), self.chunk, ACTION_SIZE), self.unseen(features)


def pixel_loss(config: PolicyConfig, model: nn.Module, batch: Batch) -> torch.Tensor:
    """Behaviour cloning, plus `UNSEEN_WEIGHT` times the squared error of the encoder's guess of the
    state it does not see (normalised). The guess is trained, never used: the policy acts on images."""
    nets = list(model.nets) if isinstance(model, Members) else [model]
    one = dataclasses.replace(config, members=1)
    total = torch.zeros(())
    for net in nets:
        actions, guess = cast(PixelChunk, net).forward_both(batch.x, *batch.images)
        actions, guess = actions.float(), guess.float()  # the loss in fp32 when training in bf16
        total = total + masked_loss(one, actions, batch.y, batch.m)
        if batch.unseen is not None and UNSEEN_WEIGHT:
            total = total + UNSEEN_WEIGHT * ((guess - batch.unseen) ** 2).mean()
    return total / len(nets)


PIXEL_CHUNK = Kind(PixelChunk, chunk_examples, ChunkActor, loss=pixel_loss, learns_unseen=True)
