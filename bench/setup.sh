#!/usr/bin/env bash
# Creates bench/.venv with the reference libraries that `voyage bench` compares against.
# Usage: bash bench/setup.sh   (needs python3 with venv and pip; network to PyPI)
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
python3 -m venv "$here/.venv"
"$here/.venv/bin/python" -m pip install -q --upgrade pip
"$here/.venv/bin/python" -m pip install -q -r "$here/requirements.txt"
echo "reference libraries installed in $here/.venv"
