#!/usr/bin/python3
"""Moves an experiment run's evaluation records into a results section, labelled.

Usage: scripts/label-records.py RUN_DIR VARIANT RECORDS_JSONL

Every record of RUN_DIR/results.jsonl gets "variant" VARIANT and "training_seconds" (the sum
of the epochs' seconds in RUN_DIR/training.jsonl); they replace the records of that variant
in RECORDS_JSONL and keep the others (scripts/generalisation-ablation.sh, architectures.sh).
"""
import json
import pathlib
import sys

out, variant, dest = pathlib.Path(sys.argv[1]), sys.argv[2], pathlib.Path(sys.argv[3])
seconds = sum(json.loads(l)["record"]["seconds"] for l in open(out / "training.jsonl") if l.strip())
kept = [l for l in (dest.read_text().splitlines() if dest.exists() else [])
        if json.loads(l).get("variant") != variant]
for l in open(out / "results.jsonl"):
    r = json.loads(l)
    r["variant"] = variant
    r["training_seconds"] = seconds
    kept.append(json.dumps(r))
dest.write_text("\n".join(kept) + "\n")
