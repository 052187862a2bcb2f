#!/usr/bin/python3
"""Where a long chain of recipes stands (docs/models.md, "Recipes"): each step of the chain whose
model exists, with its PSNR on the cross-scene light fields (sensor mode, noiseless), beside the
default's step of the same name, as a markdown table on stdout.

    scripts/chain-progress.py lfnet-learned-mask-n2-full lfnet-learned-asp-n2-full

A chain NAME's steps are the recipes NAME-<step> in configs/recipes.json order, then NAME; the
default's steps are lfnet-asp-n2-<step> and lfnet-asp-n2. LFNET (default build/apps/lfnet) is the
program, LFNET_THREADS (default 1) its --threads.
"""
import json
import os
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
LIGHT_FIELDS = [("hci_antinous", ["--lf", "../shared/data/hci_antinous"]),
                ("lytro_Begonia", ["--lf", "../shared/data/lytro_Begonia"]),
                ("heldout_window", ["--scene", "configs/scenes/heldout_window.json"]),
                ("heldout_wide", ["--scene", "configs/scenes/heldout_wide.json"])]


def fail(message):
    print("chain-progress.py: error: " + message, file=sys.stderr)
    sys.exit(1)


def psnr(model, source):
    with tempfile.NamedTemporaryFile(suffix=".json") as out:
        cmd = [os.environ.get("LFNET", "build/apps/lfnet"), "--log-level", "error", "--threads",
               os.environ.get("LFNET_THREADS", "1"), "evaluate", "--model", model, *source,
               "--mode", "sensor", "--method", "net", "--json", out.name]
        run = subprocess.run(cmd, capture_output=True, text=True)
        if run.returncode != 0:
            fail(f"{' '.join(cmd)}: {run.stderr.strip()}")
        with open(out.name) as f:
            return json.load(f)["psnr_db"]


def training_seconds(model):
    log = os.path.splitext(model)[0] + ".training.jsonl"
    if not os.path.isfile(log):
        return None
    with open(log) as f:
        return sum(json.loads(line).get("record", {}).get("seconds", 0) for line in f if line.strip())


def main():
    os.chdir(ROOT)
    chains = sys.argv[1:]
    if not chains or any(c.startswith("-") for c in chains):
        print(__doc__, file=sys.stderr)
        sys.exit(2)
    with open("configs/recipes.json") as f:
        recipes = json.load(f)["recipes"]
    print("| step | model | " + " | ".join(name for name, _ in LIGHT_FIELDS)
          + " | training s |")
    print("|---" * (len(LIGHT_FIELDS) + 3) + "|")
    row_of = {}  # model -> its row's cells: a default step shared by two chains runs once
    for chain in chains:
        steps = [r for r in recipes if r["name"].startswith(chain + "-") or r["name"] == chain]
        if not steps:
            fail(f"no recipe is called {chain} or {chain}-<step>")
        for r in steps:
            step = r["name"][len(chain) + 1:] or "last"
            default = "models/lfnet-asp-n2" + ("" if step == "last" else "-" + step) + ".ckpt"
            for model in (r["model"], default, default.replace("models/", "out/cache/", 1)):
                if not os.path.isfile(model):
                    continue
                if model not in row_of:
                    values = [f"{psnr(model, source):.2f}" for _, source in LIGHT_FIELDS]
                    seconds = training_seconds(model)
                    row_of[model] = values + ["" if seconds is None else f"{seconds:.0f}"]
                print(f"| {step} | {model} | " + " | ".join(row_of[model]) + " |")


if __name__ == "__main__":
    main()
