"""`gym-fetch generate --ray`: the same demos as the process pool, made by Ray actors on a local Ray
instance (skipped when Ray is not installed: `pip install ".[ray]"`)."""

from __future__ import annotations

import pathlib

import pytest

pytest.importorskip("ray")

from fetch.cli import main  # noqa: E402
from test_generate import collect, gen_argv, same_demos  # noqa: E402


@pytest.fixture(scope="module")
def ray_local():
    import ray

    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield
    ray.shutdown()


def test_ray_makes_the_same_demos_as_the_process_pool(ray_local: None, tmp_path: pathlib.Path) -> None:
    source = collect("PickPlace-v2", tmp_path / "src", episodes=3)
    pool, on_ray = tmp_path / "pool", tmp_path / "ray"
    assert main(gen_argv(source, pool, 10, "--workers", "2")) == 0
    assert main(gen_argv(source, on_ray, 10, "--ray", "--workers", "2")) == 0
    same_demos(pool, on_ray)
    assert main(["replay", str(on_ray), "--check"]) == 0
