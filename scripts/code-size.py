#!/usr/bin/env python3
"""The size of the code, as docs/architecture.md bounds it: the functions over N lines and the
largest files of each folder given, and the flags apps/lfnet declares in more than one file.

    scripts/code-size.py [--over N] [FOLDER ...]   (default: lfnet/src/pipeline apps/lfnet, 80)

Functions are found by braces at namespace level (a class's methods each count alone), after
comments and strings are stripped; a rough count, for the sizes the docs and issues quote.
"""
import argparse
import collections
import glob
import os
import re
import sys


def stripped(text):
    text = re.sub(r'//[^\n]*', '', text)
    text = re.sub(r'R"(\w*)\((.|\n)*?\)\1"', '""', text)
    text = re.sub(r'"(\\.|[^"\\\n])*"', '""', text)
    return re.sub(r"'(\\.|[^'\\])'", "''", text)


def functions(path):
    """(lines, path, first line, head) of every function at namespace or class level."""
    lines = stripped(open(path, encoding="utf-8").read()).split('\n')
    found, depth, scopes, start, head = [], 0, [], None, ""
    for i, line in enumerate(lines):
        for j, ch in enumerate(line):
            if ch == '{':
                before = line[:j].strip() or (lines[i - 1].strip() if i else '')
                if start is None and depth == len(scopes) and re.search(
                        r'\bnamespace\b|\bstruct\b|\bclass\b|extern "C"', before):
                    scopes.append(depth)
                    depth += 1
                    continue
                if start is None and depth == len(scopes):
                    start, head = i, before
                depth += 1
            elif ch == '}':
                depth -= 1
                if scopes and depth == scopes[-1] and start is None:
                    scopes.pop()
                    continue
                if start is not None and depth == len(scopes):
                    found.append((i - start + 1, path, start + 1, head[:70]))
                    start = None
    return found


def flag_declarations(folder):
    declared = collections.defaultdict(list)
    for path in sorted(glob.glob(os.path.join(folder, '*.cc')) + glob.glob(os.path.join(folder, '*.h'))):
        text = open(path, encoding="utf-8").read()
        for m in re.finditer(r'add_(?:option|flag)\(\s*"(--[a-z0-9-]+)[^"]*"', text):
            if os.path.basename(path) not in declared[m.group(1)]:
                declared[m.group(1)].append(os.path.basename(path))
    return declared


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--over', type=int, default=80, help='list functions longer than this')
    parser.add_argument('folders', nargs='*', default=['lfnet/src/pipeline', 'apps/lfnet'])
    args = parser.parse_args()
    for folder in args.folders:
        if not os.path.isdir(folder):
            sys.exit(f'code-size: {folder} is not a folder')
        files = sorted(glob.glob(os.path.join(folder, '*.cc')))
        found = sorted((f for path in files for f in functions(path)), reverse=True)
        sizes = sorted(((sum(1 for _ in open(p, encoding="utf-8")), p) for p in files), reverse=True)
        print(f'{folder}: {len(files)} files, {sum(n for n, _ in sizes)} lines; longest function '
              f'{found[0][0] if found else 0} lines; largest file {sizes[0][1]} ({sizes[0][0]} lines)')
        for n, path, line, head in found:
            if n > args.over:
                print(f'  {n} lines: {path}:{line} {head}')
    declared = flag_declarations('apps/lfnet')
    twice = {k: v for k, v in declared.items() if len(v) > 1}
    print(f'apps/lfnet: {len(declared)} flags, {len(twice)} declared in more than one file'
          + (': ' + ', '.join(f'{k} ({len(v)})' for k, v in sorted(twice.items())) if twice else ''))


if __name__ == '__main__':
    main()
