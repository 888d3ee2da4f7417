"""`gym-fetch generate --cameras`: each generated demo holds its cameras' images, rendered in the workers
from its states, bit-identical to what `render-obs` (and `collect --cameras`) record for those states; the
writer renders none again; a resume with other cameras and bad camera names are refused in one line."""

from __future__ import annotations

import json
import pathlib
import shutil
from typing import Any

import h5py
import numpy as np
import pytest

from fetch.cli import main
from fetch.dataset import open_dataset
from fetch.dataset.demo_file import IMAGE_CHUNK
from fetch.dataset.render.frames import StateRenderer
from fetch.dataset.validation import require_valid
from fetch.dataset.writer import DatasetWriter
from fetch.generate import attempt, run
from fetch.generate.attempt import Generator, Options
from fetch.generate.sources import load_sources
from test_generate import collect, gen_argv, same_demos

CAMERAS = ("front", "wrist")
SIZE = 32
IMAGES = ("--cameras", ",".join(CAMERAS), "--image-size", str(SIZE))
SHORT = "--stop-on-success"
"""Demos that end once success has held: fewer frames to render, and to check."""


def _no_render(*args: Any, **kwargs: Any) -> None:
    raise AssertionError("rendered outside the generate workers")


@pytest.fixture(scope="module")
def source(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    """Three PickPlace-v2 expert demos, without images."""
    return collect("PickPlace-v2", tmp_path_factory.mktemp("src") / "pick")


@pytest.fixture(scope="module")
def pooled(source: pathlib.Path, tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    """Four demos with front and wrist images from two worker processes; neither this process nor the
    writer renders (both would fail)."""
    out = tmp_path_factory.mktemp("gen") / "pooled"
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(DatasetWriter, "_render", _no_render)
        patch.setattr(attempt, "StateRenderer", _no_render)
        assert main(gen_argv(source, out, 4, "--workers", "2", SHORT, *IMAGES)) == 0
    return out


def test_every_demo_holds_the_images_render_obs_makes_of_its_states(pooled: pathlib.Path, tmp_path: pathlib.Path,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    with open_dataset(pooled) as ds:
        require_valid(ds)
        assert ds.layout.cameras == CAMERAS and ds.layout.image_size == SIZE
        assert ds.layout.image_quality == "fast"  # the default
        assert len(ds.demo_names) == 4
        with StateRenderer(ds.env_id, ds.env_kwargs, SIZE, SIZE, "fast") as renderer:
            for name in ds.demo_names:
                arrays = ds.arrays(name)
                steps = len(arrays["actions"])
                for camera in CAMERAS:
                    frames = renderer.frames(arrays["states"], camera)
                    for prefix, expected in (("obs", frames[:-1]), ("next_obs", frames[1:])):
                        images = arrays[f"{prefix}/{camera}_image"]
                        assert images.dtype == np.uint8 and images.shape == (steps, SIZE, SIZE, 3)
                        assert np.array_equal(images, expected), (name, prefix, camera)
                assert arrays["obs/front_image"].std() > 0  # not a blank frame
    assert main(["info", str(pooled)]) == 0
    assert f"cameras     front, wrist ({SIZE} px, fast quality)" in capsys.readouterr().out
    # render-obs itself, rendering the wrist camera again into a copy, writes the same arrays
    copy = tmp_path / "copy"
    shutil.copytree(pooled, copy)
    assert main(["render-obs", str(copy), "--camera", "wrist", "--size", str(SIZE), "--overwrite",
                 "--workers", "1"]) == 0
    with open_dataset(pooled) as ds, open_dataset(copy) as again:
        for name in ds.demo_names:
            for key in ("obs/wrist_image", "next_obs/wrist_image"):
                assert np.array_equal(ds.arrays(name)[key], again.arrays(name)[key]), (name, key)
            # Stored as whole frames, IMAGE_CHUNK steps to an HDF5 chunk, by generate's writer and by render-obs
            # alike (h5py's own chunks cut a frame into blocks, which made reading a demo 3x as slow).
            for images in (ds.demo(name)["obs/front_image"], again.demo(name)["next_obs/wrist_image"]):
                assert images.chunks == (min(IMAGE_CHUNK, len(images)), SIZE, SIZE, 3), (name, images.chunks)
                assert images.compression == "gzip"


def test_one_worker_in_this_process_makes_the_same_demos_and_resumes(source: pathlib.Path, pooled: pathlib.Path,
                                                                     tmp_path: pathlib.Path) -> None:
    """The serial backend renders too; a run resumed with the same cameras continues to the same demos."""
    out = tmp_path / "serial"
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(DatasetWriter, "_render", _no_render)
        assert main(gen_argv(source, out, 2, "--workers", "1", SHORT, *IMAGES)) == 0
        assert main(gen_argv(source, out, 4, "--workers", "1", SHORT, *IMAGES)) == 0
    same_demos(pooled, out)


@pytest.mark.parametrize("other", [
    ["--cameras", "front", "--image-size", str(SIZE)],
    ["--cameras", "front,wrist", "--image-size", "48"],
    ["--cameras", "front,wrist", "--image-size", str(SIZE), "--image-quality", "full"],
    [],
])
def test_a_resume_with_other_cameras_size_or_quality_is_refused_in_one_line(
        source: pathlib.Path, pooled: pathlib.Path, tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str],
        other: list[str]) -> None:
    out = tmp_path / "resumed"
    shutil.copytree(pooled, out)
    capsys.readouterr()
    assert main(gen_argv(source, out, 6, "--workers", "1", SHORT, *other)) == 2
    err = capsys.readouterr().err.strip()
    quality = other[5] if len(other) > 4 else "fast"
    asked = f"--cameras {other[1]} --image-size {other[3]} --image-quality {quality}" if other else "no --cameras"
    assert len(err.splitlines()) == 1, err
    assert f"--cameras front,wrist --image-size {SIZE} --image-quality fast" in err and asked in err, err
    with open_dataset(out) as ds:
        assert len(ds.demo_names) == 4


def test_render_obs_keeps_a_dataset_s_one_image_quality(pooled: pathlib.Path, tmp_path: pathlib.Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """A camera added to a dataset with images is drawn at their quality; asking for another is one line."""
    copy = tmp_path / "copy"
    shutil.copytree(pooled, copy)
    capsys.readouterr()
    side = ["render-obs", str(copy), "--camera", "side", "--size", str(SIZE), "--workers", "1"]
    assert main([*side, "--quality", "full"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "a dataset has one image quality, so use --quality fast" in err, err
    assert main(side) == 0
    with open_dataset(copy) as ds, StateRenderer(ds.env_id, ds.env_kwargs, SIZE, SIZE, "fast") as renderer:
        assert ds.layout.cameras == (*CAMERAS, "side") and ds.layout.image_quality == "fast"
        arrays = ds.arrays(ds.demo_names[0])
        assert np.array_equal(arrays["obs/side_image"], renderer.frames(arrays["states"], "side")[:-1])


@pytest.mark.parametrize(("more", "message"), [
    (["--cameras", "front,eye"], "unknown camera 'eye'"),
    (["--cameras", "front,front"], "--cameras names front more than once"),
    (["--cameras", "front", "--image-size", "0"], "--image-size must be a whole number of pixels from 1 to"),
])
def test_bad_cameras_are_refused_in_one_line_before_any_worker_starts(
        source: pathlib.Path, tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch, more: list[str], message: str) -> None:
    monkeypatch.setattr(run, "make_backend", _no_render)
    out = tmp_path / "x"
    assert main(gen_argv(source, out, 2, *more)) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1, err
    if "unknown" in message:
        assert "front, side, behind, wrist" in err  # the valid choices
    assert not (out / "demos.hdf5").exists()


def test_a_failed_attempt_renders_nothing_and_a_success_each_camera(source: pathlib.Path) -> None:
    sources = load_sources(source)
    for steps, success in ((3, False), (50, True)):
        generator = Generator(sources.env_id, sources.env_kwargs, sources.segments, Options(max_steps=steps), 100,
                              CAMERAS, SIZE)
        try:
            result = generator.attempt(0)
            assert result.success is success
            if success:
                assert result.demo is not None and set(result.images) == set(CAMERAS)
                shape = (len(result.demo.arrays["states"]), SIZE, SIZE, 3)
                assert all(i.shape == shape and i.dtype == np.uint8 for i in result.images.values())
            else:
                assert result.images == {} and generator._renderer is None  # no renderer even made
        finally:
            generator.close()


def test_a_source_whose_env_hides_the_goal_is_rendered_as_render_obs_renders_it(
        source: pathlib.Path, tmp_path: pathlib.Path) -> None:
    """The source's env_kwargs (hide_goal among them) make the workers' renderer, as they make render-obs', and the
    generated dataset records them, so that what renders its states later (render-obs, replay, a policy's eval)
    hides the goal as its images do."""
    hidden = tmp_path / "hidden"
    shutil.copytree(source, hidden)
    with h5py.File(hidden / "demos.hdf5", "r+") as f:
        env_args = json.loads(f["data"].attrs["env_args"])
        env_args["env_kwargs"]["hide_goal"] = True
        f["data"].attrs["env_args"] = json.dumps(env_args)
    out = tmp_path / "out"
    assert main(gen_argv(hidden, out, 1, "--workers", "1", SHORT, "--cameras", "front", "--image-size", str(SIZE))) == 0
    with open_dataset(out) as ds, StateRenderer(ds.env_id, ds.env_kwargs, SIZE, SIZE, "fast") as renderer:
        assert ds.env_kwargs == env_args["env_kwargs"]
        arrays = ds.arrays(ds.demo_names[0])
        frames = renderer.frames(arrays["states"], "front")
        assert np.array_equal(arrays["obs/front_image"], frames[:-1])
        assert np.array_equal(arrays["next_obs/front_image"], frames[1:])
