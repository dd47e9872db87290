#!/usr/bin/env python3
"""Check every relative Markdown link of the manual: README.md, CHANGELOG.md, docs/**/*.md, io/*.md.

A link's file must exist (relative to the page that links it; a folder counts), and a #anchor must
name a heading of the target page as GitHub spells its anchors (lower case, punctuation dropped,
spaces as hyphens, -1, -2, ... for repeated headings) or an explicit <a name="..."> / id="...".
Absolute URLs (http:, mailto:, ...) are not checked. Links inside fenced code blocks and inline
code are not links.

    scripts/check_links.py [--root DIR] [FILE.md ...]

Prints one line per broken link, FILE:LINE: TARGET: why, and exits 1 when there is any; exits 0
and prints a count otherwise. Python 3 standard library only.
"""
import argparse
import pathlib
import re
import sys
import unicodedata

FENCE = re.compile(r"^ {0,3}(`{3,}|~{3,})")
HEADING = re.compile(r"^ {0,3}(#{1,6})[ \t]+(.*?)[ \t]*#*[ \t]*$")
SETEXT = re.compile(r"^ {0,3}(=+|-+)[ \t]*$")
# [text](target) and ![alt](target); the text may hold one level of brackets ([`x`][y] is rare).
INLINE_LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\[\]]*\])*\]\(\s*(<[^>]*>|[^()\s]*(?:\([^()\s]*\)[^()\s]*)*)"
                         r"(?:\s+(?:\"[^\"]*\"|'[^']*'|\([^)]*\)))?\s*\)")
REFERENCE_DEF = re.compile(r"^ {0,3}\[[^\]]+\]:\s*(<[^>]*>|\S+)")
CODE_SPAN = re.compile(r"(`+)(.+?)(?<!`)\1(?!`)")
HTML_ANCHOR = re.compile(r"<a\s+[^>]*(?:name|id)\s*=\s*[\"']([^\"']+)[\"']", re.IGNORECASE)
HTML_ID = re.compile(r"\sid\s*=\s*[\"']([^\"']+)[\"']", re.IGNORECASE)
SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*:")


def strip_code_spans(line):
    """The line with every inline code span blanked (same length, so columns stay)."""
    return CODE_SPAN.sub(lambda m: " " * len(m.group(0)), line)


def lines_outside_fences(text):
    """(line number, line) of every line that is not inside a fenced code block."""
    fence = None
    for number, line in enumerate(text.splitlines(), start=1):
        m = FENCE.match(line)
        if fence is None:
            if m:
                fence = m.group(1)
                continue
            yield number, line
        elif m and m.group(1)[0] == fence[0] and len(m.group(1)) >= len(fence) \
                and not line.strip()[len(m.group(1)):].strip():
            fence = None


def heading_text(raw):
    """A heading's text as rendered: links to their text, code spans and emphasis to their content."""
    text = re.sub(r"!?\[((?:[^\[\]]|\[[^\[\]]*\])*)\]\([^)]*\)", r"\1", raw)
    text = re.sub(r"<[^>]+>", "", text)
    text = CODE_SPAN.sub(lambda m: m.group(2).strip(), text)
    return text


def github_slug(text):
    """GitHub's anchor of a heading: lower case; only letters, digits, spaces, '-' and '_' kept;
    spaces become hyphens."""
    out = []
    for ch in heading_text(text).strip().lower():
        if ch in " -_":
            out.append("-" if ch == " " else ch)
        elif unicodedata.category(ch)[0] in "LN" or unicodedata.category(ch) == "Mn":
            out.append(ch)
    return "".join(out)


def anchors_of(path, cache={}):
    """Every anchor a page offers: its headings' slugs (repeats numbered) and explicit HTML ids."""
    if path in cache:
        return cache[path]
    text = path.read_text(encoding="utf-8")
    seen = {}
    anchors = set()
    previous = None
    for _, line in lines_outside_fences(text):
        m = HEADING.match(line)
        title = m.group(2) if m else None
        if title is None and previous is not None and previous.strip() and SETEXT.match(line) \
                and not HEADING.match(previous):
            title = previous.strip()
        if title is not None:
            slug = github_slug(title)
            n = seen.get(slug, 0)
            seen[slug] = n + 1
            anchors.add(slug if n == 0 else f"{slug}-{n}")
        for m in HTML_ANCHOR.finditer(line):
            anchors.add(m.group(1))
        for m in HTML_ID.finditer(line):
            anchors.add(m.group(1))
        previous = line
    cache[path] = anchors
    return anchors


def links_of(path):
    """(line number, target) of every link in a page, outside code."""
    text = path.read_text(encoding="utf-8")
    for number, line in lines_outside_fences(text):
        plain = strip_code_spans(line)
        m = REFERENCE_DEF.match(plain)
        if m:
            yield number, m.group(1)
            continue
        for m in INLINE_LINK.finditer(plain):
            yield number, m.group(1)


def shown(path, root):
    """A path as the report names it: relative to the repository when inside it."""
    try:
        return str(path.resolve().relative_to(root))
    except ValueError:
        return str(path)


def check(path, root):
    problems = []
    for number, target in links_of(path):
        target = target.strip()
        if target.startswith("<") and target.endswith(">"):
            target = target[1:-1]
        if not target or SCHEME.match(target) or target.startswith("//"):
            continue
        file_part, _, anchor = target.partition("#")
        file_part = file_part.split("?", 1)[0]
        where = f"{shown(path, root)}:{number}: {target}"
        if file_part.startswith("/"):
            resolved = (root / file_part.lstrip("/")).resolve()
        elif file_part:
            resolved = (path.parent / file_part).resolve()
        else:
            resolved = path.resolve()
        if not resolved.exists():
            problems.append(f"{where}: no such file ({shown(resolved, root)})")
            continue
        if anchor and resolved.is_file() and resolved.suffix.lower() == ".md":
            if anchor not in anchors_of(resolved):
                problems.append(f"{where}: no heading or anchor '#{anchor}' in {shown(resolved, root)}")
    return problems


def default_pages(root):
    pages = [root / "README.md", root / "CHANGELOG.md"]
    pages += sorted((root / "docs").rglob("*.md"))
    pages += sorted((root / "io").glob("*.md"))
    return [p for p in pages if p.is_file()]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", default=pathlib.Path(__file__).resolve().parent.parent, type=pathlib.Path,
                        help="the repository (default: this script's parent folder)")
    parser.add_argument("pages", nargs="*", type=pathlib.Path,
                        help="pages to check (default: README.md, CHANGELOG.md, docs/**/*.md, io/*.md)")
    args = parser.parse_args()
    root = args.root.resolve()
    pages = [p.resolve() for p in args.pages] if args.pages else default_pages(root)
    problems = []
    count = 0
    for page in pages:
        if not page.is_file():
            problems.append(f"{page}: no such page")
            continue
        count += sum(1 for _ in links_of(page))
        problems += check(page, root)
    for p in problems:
        print(p)
    if problems:
        print(f"check_links: {len(problems)} broken of {count} links in {len(pages)} pages", file=sys.stderr)
        return 1
    print(f"check_links: {count} links in {len(pages)} pages, none broken")
    return 0


if __name__ == "__main__":
    sys.exit(main())
