#!/usr/bin/python3
"""Checks that the names the hand-written docs cite in `backticks` exist.

README.md and docs/*.md (not the generated docs/RESULTS.md) are read; in each, every inline code
span outside fenced blocks that looks like a name is looked up:

- a path into the tree (apps/, cmake/, configs/, docs/, lfnet/, models/, scripts/, tests/, .ci/,
  results/): the file or folder exists (a `*` matches as a glob);
- a C++ or Python name (`a::b`, `name()`, a snake_case word): it occurs in the sources
  (apps/, lfnet/, tests/, scripts/) or the configs;
- a flag (`--name`): it occurs in apps/ or scripts/;
- a dotted config key (`network.image.widths`): its last part occurs in the sources or configs.

Anything else (commands with spaces, values, formulas) is prose and is not checked. Then every
reference to a section, `docs/NAME.md, "Title"`, in the docs and in the sources' comments is
looked up: the doc has a heading (or a bold lead-in) that starts with the title. Prints one line
per name or section that does not exist and exits 1 if there is any.

    scripts/check-doc-names.py          # from anywhere; reads the tree this script is in
"""
import glob
import os
import re
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TREE_DIRS = ("apps/", "cmake/", "configs/", "docs/", "lfnet/", "models/", "scripts/", "tests/",
             ".ci/", "results/")
SOURCE_DIRS = ("apps", "lfnet", "tests", "scripts", "configs", "cmake")
SOURCE_EXT = (".cc", ".h", ".py", ".sh", ".json", ".txt", ".cmake", ".js", ".html", ".css")
# Names of the libraries lfnet builds on that the docs cite (LibTorch, the C++ and Python
# standard libraries, CLI11): they are not in lfnet's sources.
EXTERNAL = {"--help", "libtorch_cpu", "channels_last_3d", "out_of_range", "torch.utils.cmake_prefix_path"}


def docs():
    files = [os.path.join(ROOT, "README.md")]
    files += sorted(f for f in glob.glob(os.path.join(ROOT, "docs", "*.md"))
                    if os.path.basename(f) != "RESULTS.md")
    return files


def spans(text):
    """The inline code spans of `text` outside fenced code blocks."""
    out = []
    fenced = False
    for line in text.splitlines():
        if line.lstrip().startswith("```"):
            fenced = not fenced
            continue
        if fenced or line.startswith("    "):
            continue
        out += re.findall(r"`([^`\n]+)`", line)
    return out


def source_text():
    chunks = []
    for top in SOURCE_DIRS:
        for folder, _, files in os.walk(os.path.join(ROOT, top)):
            if "/fuzz/corpus" in folder or "/fuzz/regressions" in folder:
                continue
            for f in files:
                if f.endswith(SOURCE_EXT) or f == "CMakeLists.txt":
                    try:
                        with open(os.path.join(folder, f), encoding="utf-8") as fh:
                            chunks.append(fh.read())
                    except (UnicodeDecodeError, OSError):
                        pass
    with open(os.path.join(ROOT, "CMakeLists.txt")) as fh:
        chunks.append(fh.read())
    return "\n".join(chunks)


def check_name(name, sources):
    """None when `name` exists or is not a name; else why it does not."""
    name = name.strip()
    if name in EXTERNAL:
        return None
    path = name.split(":")[0].split("#")[0].rstrip(",.")
    if path.startswith(TREE_DIRS) and re.fullmatch(r"[\w.\-/*{}]+", path):
        if "{" in path:
            return None  # a pattern of names, not one
        # lfnet/nn/x.h is the header lfnet/include/lfnet/nn/x.h, as #include names it.
        candidates = [path]
        if path.startswith("lfnet/"):
            candidates += ["lfnet/include/" + path, "lfnet/src/" + path[len("lfnet/"):]]
        for c in candidates:
            full = os.path.join(ROOT, c)
            if glob.glob(full) if "*" in c else os.path.exists(full):
                return None
        return f"the path {path} does not exist"
    if re.fullmatch(r"--[a-z][a-z0-9-]*", name):
        return None if re.search(r'"' + re.escape(name) + r'[",\s=]', sources) else \
            f"the flag {name} occurs in no source"
    m = re.fullmatch(r"((?:[A-Za-z_]\w*::)*[A-Za-z_]\w*)(\(\))?", name)
    if m and ("::" in name or m.group(2) or re.fullmatch(r"[a-z][a-z0-9]*(_[a-z0-9]+)+", name)):
        last = m.group(1).split("::")[-1]
        return None if re.search(r"\b" + re.escape(last) + r"\b", sources) else \
            f"the name {m.group(1)} occurs in no source"
    if re.fullmatch(r"[a-z_][a-z0-9_]*(\.[a-z_][a-z0-9_]*)+", name) and "_" in name.split(".")[-1]:
        last = name.split(".")[-1]
        return None if re.search(r"\b" + re.escape(last) + r"\b", sources) else \
            f"the key {name} occurs in no source"
    return None


def titles(doc):
    """The headings and bold lead-ins of `doc`, without their marks and backticks."""
    found = []
    with open(doc, encoding="utf-8") as fh:
        for line in fh:
            m = re.match(r"#+\s+(.*)", line) or \
                re.match(r"(?:[-*]\s+)?\*\*([^*]+)\*\*", line.strip())
            if m:
                title = m.group(1).replace("`", "").strip().rstrip(".")
                found.append(re.sub(r"^\d+[a-z]?\.\s+", "", title))  # "7. End to end"
    return found


SECTION = re.compile(r'(docs/[A-Za-z_-]+\.md),? \(?"([^"\n]{3,80})"')


def section_problems():
    problems = []
    cache = {}
    files = docs() + [os.path.join(ROOT, "docs", "RESULTS.md")]
    for top in SOURCE_DIRS:
        for folder, _, names in os.walk(os.path.join(ROOT, top)):
            files += [os.path.join(folder, f) for f in names if f.endswith(SOURCE_EXT)]
    for path in files:
        if os.path.abspath(path) == os.path.abspath(__file__):
            continue
        try:
            with open(path, encoding="utf-8") as fh:
                text = fh.read()
        except (UnicodeDecodeError, OSError):
            continue
        for doc, title in SECTION.findall(text.replace("\n// ", " ").replace("\n# ", " ")):
            full = os.path.join(ROOT, doc)
            if not os.path.isfile(full):
                problems.append(f"{os.path.relpath(path, ROOT)}: {doc} does not exist")
                continue
            if full not in cache:
                cache[full] = titles(full)
            title = title.replace("`", "")
            if not any(t.startswith(title) for t in cache[full]):
                problems.append(f'{os.path.relpath(path, ROOT)}: {doc} has no section "{title}"')
    return problems


def main():
    sources = source_text()
    problems = section_problems()
    for doc in docs():
        with open(doc, encoding="utf-8") as fh:
            text = fh.read()
        for span in spans(text):
            why = check_name(span, sources)
            if why:
                problems.append(f"{os.path.relpath(doc, ROOT)}: `{span}`: {why}")
    for p in problems:
        print(p)
    if problems:
        print(f"check-doc-names: {len(problems)} name(s) or section(s) cited do not exist")
        return 1
    print(f"check-doc-names: every name cited in {len(docs())} docs, and every section cited, "
          "exists")
    return 0


if __name__ == "__main__":
    sys.exit(main())
