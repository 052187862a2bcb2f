#!/usr/bin/python3
"""Makes the records of results/<section>/records.jsonl, then regenerates docs/RESULTS.md.

    scripts/results.py [SECTION...]   # default: the data's "default" sections, in its order
    scripts/results.py pictures       # only the reconstructions the report shows
    scripts/results.py report         # nothing measured: the report from the records as they are
    MODELS="NAME_OR_FILE ..." scripts/results.py cross-scene-add  # also holdout-(colour-)add
    ONLY=PREFIX scripts/results.py SECTION...  # only the records whose variant starts with PREFIX,
                                               # made again in place of theirs
    ONLY_LF="NAME ..." scripts/results.py SECTION...  # only the light-field folders of these names
                                               # (of {"dirs"} loops), made again in place of theirs
    scripts/results.py --list         # the sections, one a line

The sections are data, configs/results.json: each names its models, light fields, methods and
flags as nested loops, and this driver expands them into `lfnet` commands (LFNET, default
build/apps/lfnet) and runs them in order. It never names a model's file: a model is a NAME that
the data's "model_files" patterns turn into the first file that exists (a word ending in .ckpt
or .json is a file already). Every model and training log a section reads is checked before
anything runs; a missing model stops the run with the recipe that makes it (scripts/models.py
make RECIPE). Needs ../shared/data.

A section's keys (all optional):
  do        the steps: {"for": {VAR: VALUES, ...}, "if"/"unless": {VAR: [VALUE, ...]}, "do": [...]}
            nests loops (the first outermost); a leaf is {"evaluate": ARGS, "variant", "training"
            (a model whose log's seconds become training_seconds), "training_if_present",
            "scene" (appends to that section's records, resumably)}, {"run": ARGS} (an lfnet
            command with no record), {"remove": [PATH, ...]} or {"kind": NAME, ...} (a named
            step of this driver, KINDS).
  before    steps run before the others are expanded ("unless_dir" skips them)
  after     steps run once the records are written
  write     replace (default: results/<records>/records.jsonl made anew), replace-variants
            (its records replace those of the same variant), scene (appended by the leaves) or
            none
  records   the section whose records it writes (default: its own)
  vars      names bound for its steps (beside the data's global "vars")
  pictures  folders emptied first
  work      a temporary folder, {work}, removed at the end
  fresh     {"env": VAR, "records": [SECTION, ...]}: VAR=1 removes those records first
In ARGS, "{VAR}" is a value (a list splices in), "{VAR|first}" a list's first, "{VAR|name}" and
"{VAR|base}" a model's name and file stem, "@NAME" a model's file; "{json}" places --json
(default: last). VALUES: a list (an object binds its keys), "{VAR}", {"env": VAR, "default" or
"required"} or {"dirs": [GLOB, ...], "with": FILE}.
"""
import glob
import json
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DATA = "configs/results.json"
PROG = "results.py"
# Values known only while a section runs: a record's temporary --json file, the section's work
# folder, and what a named step measured (light-field-size).
RUNTIME = ("json", "work", "size")
VAR = re.compile(r"\{([A-Za-z_][\w#]*)(?:\|(\w+))?\}")


class Failure(Exception):
    """One line for the user; the run stops with it."""


class Models:
    """A model NAME's file: the first of the data's patterns that exists, else the last."""

    def __init__(self, patterns):
        self.patterns = patterns

    def file(self, ref):
        if ref.endswith((".ckpt", ".json")):
            return ref
        paths = [p.replace("{}", ref) for p in self.patterns]
        return next((p for p in paths if os.path.isfile(p)), paths[-1])

    def name(self, path):
        """A file's name as a section labels it: its path less a pattern's folder and .ckpt."""
        for prefix in dict.fromkeys(p.split("{}")[0] for p in self.patterns):
            if prefix and path.startswith(prefix):
                path = path[len(prefix):]
        return path[:-len(".ckpt")] if path.endswith(".ckpt") else path

    def log(self, ref):
        f = self.file(ref)
        return (f[:-len(".ckpt")] if f.endswith(".ckpt") else f) + ".training.jsonl"


def values(spec, env, where):
    """The values a loop or a var runs over."""
    if isinstance(spec, list):
        return spec
    if isinstance(spec, str):
        m = VAR.fullmatch(spec)
        if m and not m.group(2) and isinstance(env.get(m.group(1)), list):
            return env[m.group(1)]
        raise Failure(f"{where}: {spec!r} is not a list variable")
    if "env" in spec:
        words = os.environ.get(spec["env"], "").split()
        if words:
            return words
        if "required" in spec:
            raise Failure(f"{where}: {spec['env']}: {spec['required']}")
        return spec["default"]
    if "dirs" in spec:
        found = []
        only = os.environ.get("ONLY_LF", "").split()
        for pattern in spec["dirs"]:
            found += [d for d in sorted(glob.glob(pattern))
                      if os.path.isfile(os.path.join(d, spec["with"]))
                      and (not only or os.path.basename(d) in only)]
        return found
    raise Failure(f"{where}: cannot loop over {spec!r}")


class Plan:
    """Expands a section's steps into actions, checking that the files they read exist."""

    def __init__(self, section, models, env):
        self.section, self.models, self.env = section, models, env
        self.actions = []

    def string(self, text, env, refs):
        def one(m):
            name, how = m.groups()
            if name not in env:
                if name in RUNTIME and not how:
                    return m.group(0)  # filled in when the action runs
                raise Failure(f"{self.section}: {{{name}}} is not bound")
            v = env[name]
            if how == "first":
                return str(v[0])
            if isinstance(v, (list, dict)):
                raise Failure(f"{self.section}: {{{name}}} is a list, not a word, in {text!r}")
            if how in ("name", "base"):
                path = self.models.file(str(v))
                refs.append(path)
                if how == "name":
                    return self.models.name(path)
                base = os.path.basename(path)
                return base[:-len(".ckpt")] if base.endswith(".ckpt") and base != ".ckpt" else base
            if how:
                raise Failure(f"{self.section}: unknown filter |{how} in {text!r}")
            return str(v)

        out = VAR.sub(one, text)
        if out.startswith("@"):
            out = self.models.file(out[1:])
            refs.append(out)
        return out

    def args(self, tokens, env, refs):
        out = []
        for t in tokens:
            m = VAR.fullmatch(t)
            if m and not m.group(2) and isinstance(env.get(m.group(1)), list):
                out += self.args(env[m.group(1)], env, refs)
            else:
                out.append(self.string(t, env, refs))
        return out

    def steps(self, nodes, env):
        for node in nodes:
            self.node(node, env)

    def node(self, node, env):
        loops = list(node.get("for", {}).items())

        def nest(i, env):
            if i < len(loops):
                var, spec = loops[i]
                for k, v in enumerate(values(spec, env, self.section)):
                    inner = dict(env, **{var + "#": k})
                    inner.update(v if isinstance(v, dict) else {var: v})
                    nest(i + 1, inner)
                return
            if not all(env.get(k) in vs for k, vs in node.get("if", {}).items()):
                return
            if any(env.get(k) in vs for k, vs in node.get("unless", {}).items()):
                return
            if "do" in node:
                self.steps(node["do"], env)
            else:
                self.leaf(node, env)

        nest(0, env)

    def leaf(self, node, env):
        refs, logs = [], []
        a = {"refs": refs, "logs": logs}
        if "evaluate" in node:
            a["type"] = "evaluate"
            a["variant"] = self.string(node.get("variant", ""), env, refs)
            if not a["variant"].startswith(os.environ.get("ONLY", "")):
                return
            a["args"] = self.args(node["evaluate"], env, refs)
            a["training"] = ""
            if "training" in node:
                a["training"] = self.models.log(self.string(node["training"], env, []))
                logs.append(a["training"])
            elif "training_if_present" in node:
                log = self.models.log(self.string(node["training_if_present"], env, []))
                a["training"] = log if os.path.isfile(log) else ""
            if "scene" in node:
                a["scene"] = node["scene"]
        elif "run" in node:
            a["type"] = "run"
            a["args"] = self.args(node["run"], env, refs)
        elif "remove" in node:
            a["type"] = "remove"
            a["args"] = self.args(node["remove"], env, refs)
        elif "kind" in node:
            if node["kind"] not in KINDS:
                raise Failure(f"{self.section}: unknown kind {node['kind']!r}")
            a["type"] = "kind"
            a["kind"] = node["kind"]
            a["args"] = self.args(node.get("args", []), env, refs)
        else:
            raise Failure(f"{self.section}: a step with nothing to do: {json.dumps(node)}")
        self.actions.append(a)


def need_model(path, section, recipes):
    """Stops the run unless model file `path` exists: a section never loses rows silently."""
    if os.path.isfile(path):
        return
    names = " ".join(r["name"] for r in recipes if r["model"] == path) or "?"
    raise Failure(f"{path} is missing, so {section} would lose its rows; make it first: "
                  f"scripts/models.py make {names}")


def check(plan, recipes):
    for a in plan.actions:
        for path in a["refs"]:
            need_model(path, plan.section, recipes)
        for log in a["logs"]:
            if not os.path.isfile(log):
                raise Failure(f"{log} is missing, so {plan.section} cannot label its rows "
                              "with training_seconds; it comes with its model's recipe")


def append_record(out, path, variant="", training="", run=None):
    """Appends the JSON object of file `path` as one line to `out`, labelled."""
    r = json.load(open(path))
    if variant:
        r["variant"] = variant
    if training:
        r["training_seconds"] = sum(json.loads(l)["record"]["seconds"] for l in open(training)
                                    if l.strip())
    if run:
        r["run"] = run
    open(out, "a").write(json.dumps(r) + "\n")


def replace_variants(old_path, new_path, light_fields=False):
    """Replaces the records of `old_path` whose variant is among those of `new_path`; with
    `light_fields`, only those of the same variant and light field."""
    new = [json.loads(l) for l in open(new_path) if l.strip()]
    variants = {r.get("variant") for r in new}
    lfs = {(r.get("variant"), r.get("light_field")) for r in new}

    def replaced(r):
        if light_fields:
            return (r.get("variant"), r.get("light_field")) in lfs
        return r.get("variant") in variants
    kept = [l for l in open(old_path) if l.strip() and not replaced(json.loads(l))]
    with open(old_path + ".tmp", "w") as f:
        f.writelines(kept)
        f.writelines(json.dumps(r) + "\n" for r in new)
    os.replace(old_path + ".tmp", old_path)


def recorded(file, key):
    return os.path.isfile(file) and any(json.loads(l).get("run") == key
                                        for l in open(file) if l.strip())


def light_field_size(runtime, sensor_json):
    """{size}: the HEIGHTxWIDTH of the light field of a simulated sensor's sensor.json."""
    l = json.load(open(sensor_json))["light_field"]
    runtime["size"] = str(l["height"]) + "x" + str(l["width"])


KINDS = {"light-field-size": light_field_size}


def records_file(section):
    return os.path.join("results", section, "records.jsonl")


class Runner:
    def __init__(self, data, lfnet):
        self.data, self.lfnet = data, lfnet
        self.models = Models(data["model_files"])
        self.recipes = json.load(open(data["recipes"]))["recipes"]

    def section_env(self, name):
        """The data's vars, then the section's; an env or dirs spec is read now."""
        env = {}
        for scope in (self.data.get("vars", {}), self.data["sections"][name].get("vars", {})):
            for k, v in scope.items():
                env[k] = values(v, env, name) if isinstance(v, dict) else v
        return env

    def plan(self, name, key):
        spec = self.data["sections"][name]
        p = Plan(name, self.models, self.section_env(name))
        nodes = spec.get(key, [])
        if key == "before" and "unless_dir" in spec and os.path.isdir(spec["unless_dir"]):
            nodes = []
        p.steps(nodes, p.env)
        return p

    def precheck(self, name):
        for key in ("before", "do", "after"):
            check(self.plan(name, key), self.recipes)

    def lfnet_run(self, label, args):
        print(f"[{label}] lfnet {shlex.join(args)}", flush=True)
        try:
            rc = subprocess.run([self.lfnet] + args).returncode
        except OSError as e:
            raise Failure(f"cannot run {self.lfnet} (LFNET): {e.strerror}")
        if rc != 0:
            raise Failure(f"{label.split()[0]}: lfnet {args[0] if args else ''} failed "
                          f"(exit {rc}): lfnet {shlex.join(args)}")

    def execute(self, name, plan, label, runtime, records):
        total = sum(a["type"] in ("evaluate", "run") for a in plan.actions)
        k = 0

        def fill(text):  # the RUNTIME values, known now
            return VAR.sub(lambda m: runtime.get(m.group(1), m.group(0)) if not m.group(2)
                           else m.group(0), text)

        for a in plan.actions:
            if a["type"] == "remove":
                for path in map(fill, a["args"]):
                    if os.path.isdir(path) and not os.path.islink(path):
                        shutil.rmtree(path)
                    elif os.path.lexists(path):
                        os.remove(path)
                continue
            if a["type"] == "kind":
                KINDS[a["kind"]](runtime, *map(fill, a["args"]))
                continue
            k += 1
            for path in a["refs"]:
                need_model(path, name, self.recipes)
            where = f"{label} {k}/{total}"
            if a["type"] == "run" and "{json}" not in a["args"]:
                self.lfnet_run(where, [fill(t) for t in a["args"]])
                continue
            file, run = records, os.environ.get("RUN")
            if a.get("scene"):
                file = records_file(a["scene"])
                run = a["variant"] + "|" + " ".join(a["args"])
                if recorded(file, run):
                    continue
            fd, runtime["json"] = tempfile.mkstemp()
            os.close(fd)
            try:
                args = [fill(t) for t in a["args"]]
                if a["type"] == "evaluate":
                    args = ["evaluate"] + args
                    if runtime["json"] not in args:
                        args += ["--json", runtime["json"]]
                self.lfnet_run(where, args)
                if a["type"] == "evaluate":
                    append_record(file, runtime["json"], a["variant"], a["training"], run)
            finally:
                os.remove(runtime.pop("json"))

    def run(self, name):
        spec = self.data["sections"][name]
        narrowed = os.environ.get("ONLY") or os.environ.get("ONLY_LF")
        write = "replace-variants" if narrowed else spec.get("write", "replace")
        target = records_file(spec.get("records", name))
        fresh = spec.get("fresh")
        if fresh and os.environ.get(fresh["env"], "0") == "1":
            for s in fresh["records"]:
                if os.path.exists(records_file(s)):
                    os.remove(records_file(s))
        for pics in [] if narrowed else spec.get("pictures", []):
            shutil.rmtree(pics, ignore_errors=True)
            os.makedirs(pics, exist_ok=True)
        runtime = {}
        if spec.get("work"):
            runtime["work"] = tempfile.mkdtemp()
        fd, records = tempfile.mkstemp()
        os.close(fd)
        try:
            before = self.plan(name, "before")
            check(before, self.recipes)
            self.execute(name, before, name + " before", runtime, records)
            main, after = self.plan(name, "do"), self.plan(name, "after")
            check(main, self.recipes)
            check(after, self.recipes)
            try:
                self.execute(name, main, name, runtime, records)
            except BaseException:
                if os.path.getsize(records):
                    print(f"{PROG}: {name} stopped; its records so far are in {records}",
                          file=sys.stderr)
                    records = None
                raise
            if write == "replace":
                shutil.copyfile(records, target + ".tmp")
                os.replace(target + ".tmp", target)
            elif write == "replace-variants":
                replace_variants(target, records, bool(os.environ.get("ONLY_LF")))
            self.execute(name, after, name + " after", runtime, records)
        finally:
            if records:
                os.remove(records)
            if "work" in runtime:
                shutil.rmtree(runtime["work"], ignore_errors=True)


def main(argv):
    os.chdir(ROOT)
    data = json.load(open(DATA))
    sections = data["sections"]
    if argv[:1] in (["-h"], ["--help"]):
        print(__doc__.strip())
        return 0
    if argv[:1] == ["--list"]:
        print("\n".join(list(sections) + ["report"]))
        return 0
    names = argv or data["default"]
    unknown = [s for s in names if s not in sections and s != "report"]
    if unknown:
        raise Failure(f"unknown section {unknown[0]!r} (scripts/results.py --list names them)")
    runner = Runner(data, os.environ.get("LFNET") or "build/apps/lfnet")
    for s in names:
        if s != "report":
            runner.precheck(s)
    for s in names:
        print(f"== {s}", flush=True)
        if s != "report":
            runner.run(s)
    runner.lfnet_run("report", data["report"])
    return 0


if __name__ == "__main__":
    signal.signal(signal.SIGPIPE, signal.SIG_DFL)  # `scripts/results.py --help | head` ends quietly
    try:
        sys.exit(main(sys.argv[1:]))
    except Failure as e:
        print(f"{PROG}: {e}", file=sys.stderr)
        sys.exit(1)
    except KeyboardInterrupt:
        sys.exit(130)
