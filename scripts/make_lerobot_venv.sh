#!/usr/bin/env bash
# A virtualenv with lerobot 0.4.4 (the newest that installs on Python 3.11) and this package, for
# tests/test_lerobot_consumer.py: lerobot's own LeRobotDataset loads `gym-fetch export --to lerobot`.
#
#   bash scripts/make_lerobot_venv.sh [DIR]        # default .venv-lerobot, next to pyproject.toml
#   HF_HUB_OFFLINE=1 DIR/bin/python -m pytest -q tests/test_lerobot_consumer.py
#
# lerobot 0.4.4 asks for torch<2.11 and torchvision<0.26, and from PyPI those are CUDA builds of
# several GB to download. It is installed without its dependencies instead, beside torch 2.14.1 and
# torchvision 0.29.1, which this machine keeps on disk (pip takes them from there; a CUDA build too,
# ~5 GB in the venv, but no download), and torchcodec 0.14 (torch 2.14's), the video decoder lerobot
# uses; torchvision 0.29 has no video reader. torchcodec needs FFmpeg's shared libraries (Debian's).
# Only what lerobot.datasets imports is installed of lerobot's other dependencies, in its ranges.
set -euo pipefail
cd "$(dirname "$0")/.."
venv=${1:-.venv-lerobot}
if ! ldconfig -p | grep libavformat.so > /dev/null; then  # (grep -q would end the pipe early: pipefail)
    apt-get update -q
    DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends \
        libavcodec59 libavformat59 libavutil57 libswscale6 libswresample4 libavdevice59 libavfilter8
fi
python3 -m venv "$venv"
"$venv/bin/pip" install -q --no-compile torch==2.14.1 torchvision==0.29.1
"$venv/bin/pip" install -q --no-deps lerobot==0.4.4 torchcodec==0.14.0
"$venv/bin/pip" install -q "datasets>=4,<5" "huggingface-hub>=0.34.2,<0.36" "av>=15,<16" "packaging>=24.2,<26" \
    "accelerate>=1.10,<2" "draccus==0.10.0" "jsonlines>=4,<5" "deepdiff>=7.0.1,<9" "termcolor>=2.4,<4" \
    "einops>=0.8,<0.9" pandas pyarrow pytest
"$venv/bin/pip" install -q -e .
"$venv/bin/python" -c "import lerobot.datasets.lerobot_dataset, torchcodec.decoders, fetch; print('lerobot venv ready')"
