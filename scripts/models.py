#!/usr/bin/python3
"""Makes the models of models/ from their recipes (configs/recipes.json; docs/models.md, "Recipes").

Every model is one config run by one lfnet command at one scale. A config may extend another
($.extends) and start from a model ($.init), distil one ($.distill.teacher) or start its learned
code from one ($.code.from): those inputs are read from the config as lfnet resolves it (`lfnet
train CONFIG --show-config`: its bases and its scale merged in), and a recipe whose model is an
input of another is made first. A `blend` recipe's config names
a finetuned model, its base and alpha ($.blend; `lfnet blend`) instead of training. A model
outside the zoo (models/zoo.json) -- a research variant, or a step of a long chain -- is made into
out/ (out/cache/ or out/chains/, the recipe's model path) rather than models/; it is made again
where missing.

    scripts/models.py list                 # every recipe, its inputs, whether its model exists
    scripts/models.py check                # every config valid, every model in models/ has a recipe
    scripts/models.py make NAME [NAME...]  # make missing models (and their missing inputs)
    scripts/models.py make --force NAME    # make NAME again, even if its model exists

`make` is resumable: each run goes to out/models/NAME, and running it again after an
interruption continues the run (`--resume`). The model of the run's last stage is copied to the
recipe's model path whole or not at all, with its training log beside it (NAME.training.jsonl;
`log.after` puts the log of the model it was finetuned from first). LFNET (default
build/apps/lfnet) is the program; LFNET_THREADS (default 1: it runs beside other work) its
--threads.
"""
import argparse
import json
import os
import shutil
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RECIPES = os.path.join("configs", "recipes.json")


def fail(message):
    print("models.py: error: " + message, file=sys.stderr)
    sys.exit(1)


def lfnet():
    return os.environ.get("LFNET", "build/apps/lfnet")


def load_recipes():
    with open(RECIPES) as f:
        recipes = json.load(f)["recipes"]
    by_name = {}
    for r in recipes:
        for key in ("name", "model", "config", "scale", "command"):
            if key not in r:
                fail(f"{RECIPES}: recipe {r.get('name', '?')} has no '{key}'")
        if r["name"] in by_name:
            fail(f"{RECIPES}: two recipes are called {r['name']}")
        if r["command"] not in ("train", "experiment", "blend"):
            fail(f"{RECIPES}: {r['name']}: command must be train, experiment or blend")
        by_name[r["name"]] = r
    for r in recipes:
        after = r.get("log", {}).get("after")
        if after is not None and after not in by_name:
            fail(f"{RECIPES}: {r['name']}: log.after names no recipe ('{after}')")
    return recipes, by_name


def scale_args(recipe):
    return ["--scale", recipe["scale"]] if recipe["scale"] else []


_resolved = {}


def recipe_config(recipe):
    """The recipe's config at its scale as lfnet resolves it (`lfnet train CONFIG --show-config`:
    $.extends, the scale -- the config's default where the recipe names none -- merged in; the
    models it starts from need not be made yet). A blend recipe's config is read as it is: it
    names two models and an alpha, and extends nothing."""
    key = (recipe["config"], recipe["scale"], recipe["command"])
    if key in _resolved:
        return _resolved[key]
    if recipe["command"] == "blend":
        with open(recipe["config"]) as f:
            config = json.load(f)
        if "extends" in config:
            fail(f"{recipe['name']}: a blend recipe's config extends nothing ($.extends)")
        config["scale"] = recipe["scale"]
    else:
        shown = subprocess.run([lfnet(), "--log-level", "error", "train", recipe["config"]]
                               + scale_args(recipe) + ["--show-config"],
                               capture_output=True, text=True)
        if shown.returncode != 0:
            fail(f"{recipe['name']}: {shown.stderr.strip()}")
        config = json.loads(shown.stdout)
    _resolved[key] = config
    return config


def inputs_of(config):
    """The model files a config starts from, distils, takes its code from or measures with."""
    found = []
    if config.get("init"):
        found.append(("starts from", config["init"]))
    phi = config.get("phi")
    if isinstance(phi, str) and phi.endswith(".ckpt"):
        found.append(("measures with the code of", phi))
    teacher = config.get("distill", {}).get("teacher")
    if teacher:
        found.append(("distils", teacher))
    code_from = config.get("code", {}).get("from")
    if code_from:
        found.append(("takes its code from", code_from))
    blend = config.get("blend", {})
    if blend.get("model"):
        found.append(("blends", blend["model"]))
    if blend.get("base"):
        found.append(("with", blend["base"]))
    return found


def blend_args(recipe):
    """`lfnet blend` arguments of a blend recipe ($.blend: model, base, alpha), checked."""
    blend = recipe_config(recipe).get("blend")
    if not isinstance(blend, dict) or not blend.get("model") or not blend.get("base"):
        fail(f"{recipe['name']}: a blend recipe's config needs $.blend.model and $.blend.base")
    alpha = blend.get("alpha", 0.5)
    if not isinstance(alpha, (int, float)) or not 0 <= alpha <= 1:
        fail(f"{recipe['name']}: $.blend.alpha must be a number in [0, 1], got {alpha!r}")
    return ["--model", blend["model"], "--base", blend["base"], "--alpha", repr(float(alpha))]


def dependencies(recipe, by_model):
    return [by_model[path] for _, path in inputs_of(recipe_config(recipe)) if path in by_model]


def cmd_list(recipes, by_name):
    for r in recipes:
        config = recipe_config(r)
        state = "exists" if os.path.isfile(r["model"]) else "missing"
        inputs = "; ".join(f"{how} {path}" for how, path in inputs_of(config))
        scale = config["scale"] or "default"
        print(f"{r['name']:<36} {state:<8} {r['command']} {r['config']} ({scale})"
              + (f"; {inputs}" if inputs else ""))


def cmd_check(recipes, by_name):
    problems = []
    waiting = []  # recipes whose inputs other recipes have not made yet: lfnet cannot check them
    by_model = {r["model"]: r for r in recipes}
    for r in recipes:
        inputs = inputs_of(recipe_config(r))
        for how, path in inputs:
            if path not in by_model and not os.path.isfile(path):
                problems.append(f"{r['name']}: {how} {path}, which no recipe makes")
        if any(path in by_model and not os.path.isfile(path) for _, path in inputs):
            waiting.append(r["name"])
            continue
        if r["command"] == "blend":
            blend_args(r)  # lfnet checks the two models when it blends them
            continue
        check = subprocess.run([lfnet(), "--log-level", "error", "train", r["config"]]
                               + scale_args(r) + ["--check"], capture_output=True, text=True)
        if check.returncode != 0:
            problems.append(f"{r['name']}: {check.stderr.strip()}")
    shipped = []
    for folder, _, files in os.walk("models"):
        shipped += [os.path.join(folder, f) for f in files if f.endswith(".ckpt")]
    for path in sorted(shipped):
        if path not in by_model:
            problems.append(f"{path} has no recipe in {RECIPES}")
    # The zoo's checkpoints are made where the zoo reads them; its cards name their recipes.
    with open(os.path.join("models", "zoo.json")) as f:
        cards = json.load(f)["models"]
    for card in cards:
        file = os.path.join("models", card["file"])
        if not os.path.isfile(file):
            problems.append(f"models/zoo.json: {card['name']}: {file} does not exist")
        for recipe in (name.strip() for name in card.get("recipe", "").split(",")):
            if recipe not in by_name:
                problems.append(f"models/zoo.json: {card['name']}: no recipe is called {recipe}")
            elif file.endswith(".ckpt") and len(card["recipe"].split(",")) == 1 \
                    and by_name[recipe]["model"] != file:
                problems.append(f"models/zoo.json: {card['name']}: its recipe {recipe} makes "
                                f"{by_name[recipe]['model']}, not {file}")
    for p in problems:
        print(p, file=sys.stderr)
    if problems:
        fail(f"{len(problems)} problem(s) in {len(recipes)} recipes")
    print(f"{len(recipes)} recipes: every config is valid at its scale, every input is made by a "
          f"recipe, each of the {len(shipped)} models in models/ has one, and each of the "
          f"{len(cards)} zoo cards names its file and recipe")
    if waiting:
        print(f"{len(waiting)} recipes wait for models that other recipes make (`make` makes "
              f"those first); lfnet checks their configs once those exist: {', '.join(waiting)}")


def compose_log(recipe, by_name, out):
    own = os.path.join(out, "training.jsonl")
    target = os.path.splitext(recipe["model"])[0] + ".training.jsonl"
    lines = []
    after = recipe.get("log", {}).get("after")
    if after:
        first = os.path.splitext(by_name[after]["model"])[0] + ".training.jsonl"
        with open(first) as f:
            lines += [line for line in f.read().splitlines() if line]
    stage = recipe.get("log", {}).get("stage")
    if os.path.isfile(own):
        with open(own) as f:
            for line in f.read().splitlines():
                if not line:
                    continue
                if stage:
                    entry = json.loads(line)
                    entry["stage"] = stage
                    line = json.dumps(entry, separators=(",", ":"))
                lines.append(line)
    with open(target + ".tmp", "w") as f:
        f.write("".join(line + "\n" for line in lines))
    os.replace(target + ".tmp", target)


def make(recipe, by_name, by_model, force, making):
    name = recipe["name"]
    if name in making:
        fail(f"{name}: its inputs make a cycle ({' -> '.join(making + [name])})")
    if os.path.isfile(recipe["model"]) and not force:
        print(f"== {name}: {recipe['model']} exists, skipped")
        return
    for dep in dependencies(recipe, by_model):
        make(dep, by_name, by_model, False, making + [name])
    if recipe["command"] == "blend":
        os.makedirs(os.path.dirname(recipe["model"]) or ".", exist_ok=True)
        cmd = [lfnet(), "blend"] + blend_args(recipe) + ["--out", recipe["model"], "--force"]
        print(f"== {name}: {' '.join(cmd[1:])}", flush=True)
        if subprocess.run(cmd).returncode != 0:  # lfnet writes the model whole or not at all
            fail(f"{name}: {' '.join(cmd)} failed")
        compose_log(recipe, by_name, os.path.join("out", "models", name))
        print(f"== {name}: {recipe['model']}", flush=True)
        return
    out = os.path.join("out", "models", name)
    threads = os.environ.get("LFNET_THREADS", "1")
    base = [lfnet(), "--threads", threads, recipe["command"]]
    if os.path.isfile(os.path.join(out, "config.json")) and not force:
        print(f"== {name}: resuming {out}", flush=True)
        cmd = base + ["--resume", out]
    else:
        print(f"== {name}: {recipe['command']} {recipe['config']} -> {out}", flush=True)
        cmd = base + [recipe["config"]] + scale_args(recipe) + ["--out", out]
        if force:
            cmd.append("--force")
    if subprocess.run(cmd).returncode != 0:
        fail(f"{name}: {' '.join(cmd)} failed")
    with open(os.path.join(out, "config.json")) as f:
        stages = json.load(f)["stages"]
    last = stages[-1] if isinstance(stages[-1], str) else stages[-1]["name"]
    trained = os.path.join(out, "models", last + ".ckpt")
    os.makedirs(os.path.dirname(recipe["model"]) or ".", exist_ok=True)
    shutil.copyfile(trained, recipe["model"] + ".tmp")
    os.replace(recipe["model"] + ".tmp", recipe["model"])
    compose_log(recipe, by_name, out)
    print(f"== {name}: {recipe['model']}", flush=True)


def main():
    os.chdir(ROOT)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="what", required=True)
    sub.add_parser("list", help="every recipe, its inputs, whether its model exists")
    sub.add_parser("check", help="every config valid, every model in models/ has a recipe")
    m = sub.add_parser("make", help="make missing models and their missing inputs")
    m.add_argument("names", nargs="+", metavar="NAME")
    m.add_argument("--force", action="store_true", help="make the named models again")
    args = parser.parse_args()
    if not os.path.isfile(lfnet()):
        fail(f"{lfnet()} is not built: run scripts/build.sh (or set LFNET)")
    recipes, by_name = load_recipes()
    if args.what == "list":
        cmd_list(recipes, by_name)
    elif args.what == "check":
        cmd_check(recipes, by_name)
    else:
        by_model = {r["model"]: r for r in recipes}
        for n in args.names:
            if n not in by_name:
                fail(f"unknown recipe '{n}' (known: {', '.join(by_name)})")
        for n in args.names:
            make(by_name[n], by_name, by_model, args.force, [])


if __name__ == "__main__":
    main()
