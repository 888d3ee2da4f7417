"""The rules robomimic's SequenceDataset and its info script apply to a dataset file.

robomimic itself is not installed here (it needs torch); this opens the file as it does and
checks what it reads, so a test fails where robomimic would.
"""

from __future__ import annotations

import json
import pathlib

import h5py
import numpy as np


def assert_robomimic_loadable(path: pathlib.Path, obs_keys: tuple[str, ...] = ("observation", "achieved_goal",
                                                                              "desired_goal")) -> None:
    with h5py.File(path, "r", swmr=True, libver="latest") as f:  # how robomimic opens it
        env_args = json.loads(f["data"].attrs["env_args"])
        assert {"env_name", "type", "env_kwargs"} <= set(env_args)
        demos = list(f["data"].keys())
        inds = np.argsort([int(elem[5:]) for elem in demos])  # robomimic's own sort
        demos = [demos[i] for i in inds]
        for key in ("train", "valid"):
            listed = [elem.decode("utf-8") for elem in np.array(f[f"mask/{key}"][:])]
            assert set(listed) <= set(demos)
        for ep in demos:
            n = f[f"data/{ep}"].attrs["num_samples"]
            assert f[f"data/{ep}/actions"].ndim == 2 and f[f"data/{ep}/actions"].shape[0] == n
            a = f[f"data/{ep}/actions"][()]
            assert a.min() >= -1.0 and a.max() <= 1.0
            for k in obs_keys:
                for prefix in ("obs", "next_obs"):
                    assert f[f"data/{ep}/{prefix}/{k}"].shape[0] == n, (ep, prefix, k)
                    if k.endswith("_image"):  # robomimic's image modality: uint8 (H, W, 3)
                        ds = f[f"data/{ep}/{prefix}/{k}"]
                        assert ds.dtype == np.uint8 and ds.ndim == 4 and ds.shape[-1] == 3
            for k in ("rewards", "dones"):
                assert f[f"data/{ep}/{k}"].shape[0] == n
