#!/usr/bin/env bash
# Make tests/data/sessions-py311 (see README.md): three demo sessions recorded by
# Python 3.11 with the code of commit 29266ad. Run from the repository root:
#   bash tests/data/sessions-py311/make_sessions_py311.sh OUT
set -euo pipefail
out=$1
python=${PYTHON:-.venv/bin/python}
"$python" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))' \
  || { echo "needs Python 3.11: its sum() is the order the records keep" >&2; exit 1; }
for arguments in \
  "--seed 31 --p-wrong-green 0.2 --p-wrong-red 0.1" \
  "--seed 32 --variant pilot --p-wrong-green 0.15 --p-no-answer 0.2" \
  "--seed 33 --language de --p-wrong-green 0.25"; do
  # shellcheck disable=SC2086  # the arguments are words
  "$python" -m kasparctl demo --fast $arguments --state-dir "$out/state" --json | tail -n 1
done
