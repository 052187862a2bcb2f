#!/usr/bin/env bash
# Makes the records of results/<section>/records.jsonl, then regenerates docs/RESULTS.md with
# `lfnet report`: scripts/results.py runs the sections that configs/results.json describes.
# Usage: scripts/results.sh [SECTION...]   (scripts/results.py --help)
exec /usr/bin/python3 "$(dirname "$0")/results.py" "$@"
