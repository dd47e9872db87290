#!/usr/bin/env python3
"""Function lengths of C++ sources: every function body at namespace or class level, in lines
from its signature's first line to its closing brace.

    scripts/function_lengths.py [--max N] FILE_OR_DIR...

Prints `file:line: name: N lines` for each function longer than --max (default 80) and exits 1
when there is one; without --max prints every function. A brace-matching reader, not a parser:
comments, strings and character literals are skipped; a body is a `{` that follows `)` (after
qualifiers such as const, override, noexcept, -> type, or a constructor's initializer list) at
namespace or class depth (a brace right after a name, `=`, `,` or `(` is an initializer); lambdas
inside a body count toward that body.
"""
import argparse
import re
import sys
from pathlib import Path


def strip(text):
    """The text with comments, strings and character literals blanked (newlines kept)."""
    out, i, n = [], 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i)); i = j
        elif text.startswith("/*", i):
            j = text.find("*/", i + 2)
            j = n if j < 0 else j + 2
            out.append(re.sub(r"[^\n]", " ", text[i:j])); i = j
        elif text.startswith('R"', i):
            m = re.match(r'R"([^(]*)\(', text[i:])
            end = text.find(")" + m.group(1) + '"', i) if m else -1
            j = n if end < 0 else end + len(m.group(1)) + 2
            out.append(re.sub(r"[^\n]", " ", text[i:j])); i = j
        elif c in "\"'":
            j = i + 1
            while j < n and text[j] != c:
                j += 2 if text[j] == "\\" else 1
            j = min(j + 1, n)
            out.append(re.sub(r"[^\n]", " ", text[i:j])); i = j
        else:
            out.append(c); i += 1
    return "".join(out)


def functions(path):
    """(first line, name, lines) of every function body in the file."""
    text = strip(path.read_text())
    found = []
    depth_kinds = []          # per open brace: "body" or "scope" (namespace, class, extern, init)
    i = 0
    stmt_start = 0            # where the current declaration began (after ; { or })
    while i < len(text):
        c = text[i]
        if c == "{":
            head = text[stmt_start:i]
            in_body = any(k[0] == "body" for k in depth_kinds)
            if not in_body and re.search(r"[\w>\]]$|[=,(]\s*$", head):
                # A brace initializer (a member's `a_{1}`, `T x{...}`, `= {...}`, an argument; a
                # body's brace follows a space): the statement goes on after it.
                depth_kinds.append(("init", 0, ""))
                i += 1
                continue
            while re.search(r"\{[^{}]*\}", head):          # initializers already read
                head = re.sub(r"\{[^{}]*\}", "", head)
            is_function = (not in_body and re.search(r"\)\s*(const|override|final|noexcept|mutable|try|"
                                                       r"requires\b[^;{]*|->[^;{]*|\s|&|\w+\s*\([^)]*\)|,|:[^;{]*)*$", head)
                           and not re.match(r"\s*(namespace|class|struct|enum|union|extern)\b", head.strip() + " "))
            if is_function:
                name_match = re.findall(r"([~\w:]+(?:<[^;{]*?>)?|operator\S+)\s*\(", head)
                first = text.count("\n", 0, stmt_start + len(head) - len(head.lstrip())) + 1
                depth_kinds.append(("body", first, name_match[0] if name_match else "?"))
            else:
                depth_kinds.append(("scope", 0, ""))
            stmt_start = i + 1
        elif c == "}":
            if depth_kinds:
                kind = depth_kinds.pop()
                if kind[0] == "init":
                    i += 1
                    continue
                if kind[0] == "body" and not any(k[0] == "body" for k in depth_kinds):
                    last = text.count("\n", 0, i) + 1
                    found.append((kind[1], kind[2], last - kind[1] + 1))
            stmt_start = i + 1
        elif c == ";" and not (depth_kinds and depth_kinds[-1][0] == "init"):
            stmt_start = i + 1
        elif c == ":" and re.search(r"\b(public|private|protected)\s*$", text[stmt_start:i]):
            stmt_start = i + 1
        i += 1
    return found


def main(argv):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--max", type=int)
    ap.add_argument("paths", nargs="+")
    a = ap.parse_args(argv)
    files = []
    for p in map(Path, a.paths):
        files += sorted(p.rglob("*.cpp")) + sorted(p.rglob("*.hpp")) if p.is_dir() else [p]
    long = 0
    for f in files:
        for line, name, n in functions(f):
            if a.max is None or n > a.max:
                print(f"{f}:{line}: {name}: {n} lines")
                long += a.max is not None
    return 1 if long else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
