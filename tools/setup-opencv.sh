#!/usr/bin/env bash
# Own Python environment for the OpenCV comparison (tools/opencv_compare.py), in tools/.venv.
set -euo pipefail
cd "$(dirname "$0")"
python3 -m venv .venv
.venv/bin/pip install --quiet --upgrade pip
.venv/bin/pip install --quiet opencv-python-headless numpy
.venv/bin/python -c "import cv2; print('OpenCV', cv2.__version__, 'in tools/.venv')"
