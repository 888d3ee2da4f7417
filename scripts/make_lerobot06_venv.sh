#!/usr/bin/env bash
# A virtualenv with lerobot 0.6 (Python >= 3.12), this package and its LeRobot env plugin
# (plugins/lerobot_env_fetch), for tests/test_lerobot_env.py: lerobot's own make_env, lerobot-train and
# lerobot-eval on our tasks and exports.
#
#   bash scripts/make_lerobot06_venv.sh [DIR]        # default .venv-lerobot06, next to pyproject.toml
#   HF_HUB_OFFLINE=1 DIR/bin/python -m pytest -q tests/test_lerobot_env.py
#
# torchcodec needs FFmpeg's shared libraries; without them lerobot decodes video with PyAV, which it does here.
set -euo pipefail
cd "$(dirname "$0")/.."
venv=${1:-.venv-lerobot06}
python=${PYTHON312:-}
if [ -z "$python" ]; then
    for candidate in python3.12 ~/.pyenv/versions/3.12.*/bin/python3 python3.13; do  # 3.12: what it is tested on
        if command -v "$candidate" >/dev/null 2>&1 \
                && "$candidate" -c 'import sys; sys.exit(sys.version_info < (3, 12))' 2>/dev/null; then
            python=$candidate
            break
        fi
    done
fi
if [ -z "$python" ]; then
    echo "make_lerobot06_venv: lerobot 0.6 needs Python >= 3.12, and none was found (set PYTHON312)" >&2
    exit 1
fi
"$python" -m venv "$venv"
"$venv/bin/pip" install -q --no-compile -e ".[lerobot]" -e plugins/lerobot_env_fetch pytest
"$venv/bin/python" -c "import lerobot, lerobot_env_fetch, fetch; print('lerobot', lerobot.__version__, 'venv ready')"
