#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""List the functions of C++ source files by length (lines from the signature's opening brace
to its closing brace, both included), longest first.

Used for issue 27's acceptance ("no function in source/ is longer than 150 lines, except the
compute kernels doc/manual/architecture.md names"):

    contrib/utilities/function_lengths.py source --over 150

A function is a brace block opened at namespace scope (or inside a class body at namespace
scope, for in-class member definitions) whose preceding text ends with ')' plus qualifiers;
lambdas and nested blocks count towards the function that holds them. Comments, string and
character literals are blanked before counting braces. Exits 1 when --over is given and a
function exceeds it.
"""
import argparse
import pathlib
import re
import sys


def blank(text):
    """Replace comments and literals by spaces, keeping newlines (line numbers stay)."""
    out, i, n = [], 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith('//', i):
            j = text.find('\n', i)
            j = n if j < 0 else j
            out.append(' ' * (j - i)); i = j
        elif text.startswith('/*', i):
            j = text.find('*/', i + 2)
            j = n if j < 0 else j + 2
            out.append(''.join(ch if ch == '\n' else ' ' for ch in text[i:j])); i = j
        elif c == 'R' and text.startswith('R"', i):
            m = re.match(r'R"([^(]*)\(', text[i:])
            end = ')' + m.group(1) + '"'
            j = text.find(end, i) + len(end)
            out.append(''.join(ch if ch == '\n' else ' ' for ch in text[i:j])); i = j
        elif c in '"\'':
            j = i + 1
            while j < n and text[j] != c:
                j += 2 if text[j] == '\\' else 1
            j += 1
            out.append(' ' * (j - i)); i = j
        else:
            out.append(c); i += 1
    return ''.join(out)


def functions(path):
    text = blank(path.read_text())
    stack = []          # kinds of the open blocks: 'ns', 'class', 'fn', 'block'
    start = 0           # index after the last ';', '{' or '}' at the current level
    found = []
    for i, c in enumerate(text):
        if c == '{':
            head = text[start:i]
            inside_fn = any(k[0] == 'fn' for k in stack)
            if inside_fn:
                kind = 'block'
            elif re.search(r'\b(namespace|extern\s*"C")\b', head):
                kind = 'ns'
            elif re.search(r'\b(class|struct|union|enum)\b[^()]*$', head):
                kind = 'class'
            elif re.search(r'\)\s*(const|noexcept|override|final|mutable|->[^{]*|:[^{]*|\s)*$',
                           head, re.S):
                kind = 'fn'
                name = re.findall(r'([~\w:]+(?:<[^<>]*>)?)\s*\(', head)
                found_start = text.count('\n', 0, i) + 1
                stack.append(('fn', name[0] if name else '?', found_start))
                start = i + 1
                continue
            else:
                kind = 'block'
            stack.append((kind, None, None))
            start = i + 1
        elif c == '}':
            if stack:
                kind, name, line = stack.pop()
                if kind == 'fn':
                    end = text.count('\n', 0, i) + 1
                    found.append((end - line + 1, name, line))
            start = i + 1
        elif c == ';':
            start = i + 1
    return found


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('paths', nargs='+')
    ap.add_argument('--over', type=int, default=None, help='list only functions longer than this')
    ap.add_argument('--top', type=int, default=20)
    args = ap.parse_args()
    rows = []
    for p in args.paths:
        p = pathlib.Path(p)
        files = sorted(p.rglob('*.cc')) + sorted(p.rglob('*.h')) if p.is_dir() else [p]
        for f in files:
            rows += [(n, name, f, line) for n, name, line in functions(f)]
    rows.sort(key=lambda r: -r[0])
    if args.over is not None:
        rows = [r for r in rows if r[0] > args.over]
    else:
        rows = rows[:args.top]
    for n, name, f, line in rows:
        print(f'{n:5d}  {f}:{line}  {name}')
    return 1 if args.over is not None and rows else 0


if __name__ == '__main__':
    sys.exit(main())
