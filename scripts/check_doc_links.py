#!/usr/bin/env python3
"""Checks the relative links of the repository's Markdown files.

Every link `[text](target)`, image `![alt](target)`, HTML `<img src>` or `<a href>` and
reference definition `[name]: target` outside code must name an existing file or directory, relative to the file it is in; a
`#anchor` (alone, or after a Markdown file) must be a heading of that file, by GitHub's rules
for heading ids, or an explicit `id`/`name` attribute. Links with a scheme (https:, mailto:)
are not followed.

Usage: python3 scripts/check_doc_links.py [FILE.md ...]   (default: every *.md in the
repository but target/ and hidden directories). Exit status 0 when every link resolves, 1
otherwise, with one line per broken link.
"""

import os
import re
import sys
from urllib.parse import unquote

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SKIP_DIRS = {"target", "node_modules"}

FENCE = re.compile(r"^ {0,3}(`{3,}|~{3,})")
INLINE_CODE = re.compile(r"(`+)(.+?)\1")
# [text](target "title") and ![alt](target); the text may hold one level of brackets.
INLINE_LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]*)>?(?:\s+\"[^\"]*\")?\s*\)")
REFERENCE_DEF = re.compile(r"^ {0,3}\[[^\]]+\]:\s*<?(\S+?)>?(?:\s|$)")
HEADING = re.compile(r"^ {0,3}(#{1,6})\s+(.*?)\s*#*\s*$")
HTML_LINK = re.compile(r"""<(?:img|a)\b[^>]*?\b(?:src|href)\s*=\s*["']([^"']+)["']""")
HTML_ID = re.compile(r"""<[^>]+\b(?:id|name)\s*=\s*["']([^"']+)["']""")
SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*:")


def markdown_files():
    for top, dirs, files in os.walk(ROOT):
        dirs[:] = sorted(d for d in dirs if not d.startswith(".") and d not in SKIP_DIRS)
        for name in sorted(files):
            if name.endswith(".md"):
                yield os.path.join(top, name)


def lines_outside_fences(text):
    """(line number, line) of every line not inside a fenced code block."""
    fence = None
    for number, line in enumerate(text.split("\n"), 1):
        match = FENCE.match(line)
        if fence is None:
            if match:
                fence = match.group(1)
                continue
            yield number, line
        elif match and match.group(1)[0] == fence[0] and len(match.group(1)) >= len(fence):
            fence = None


def heading_text(raw):
    """A heading's text as GitHub renders it: inline code kept as its text, links as their
    text, emphasis and HTML tags dropped."""
    text = INLINE_CODE.sub(lambda m: m.group(2), raw)
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", text)
    text = re.sub(r"<[^>]+>", "", text)
    return text


def slug(text):
    """GitHub's heading id: lower case; everything but letters, digits, spaces, hyphens and
    underscores removed; each space a hyphen."""
    text = heading_text(text).strip().lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


_anchor_cache = {}


def anchors(path):
    """Every anchor a Markdown file defines (headings with GitHub's -1, -2 suffixes for
    repeats, and explicit id/name attributes)."""
    if path in _anchor_cache:
        return _anchor_cache[path]
    with open(path, encoding="utf-8") as f:
        text = f.read()
    found = set()
    seen = {}
    for _, line in lines_outside_fences(text):
        match = HEADING.match(line)
        if match:
            base = slug(match.group(2))
            count = seen.get(base, 0)
            seen[base] = count + 1
            found.add(base if count == 0 else f"{base}-{count}")
        for name in HTML_ID.findall(line):
            found.add(name)
    _anchor_cache[path] = found
    return found


def links(text):
    """(line number, target) of every link outside code."""
    for number, line in lines_outside_fences(text):
        bare = INLINE_CODE.sub("", line)
        for match in INLINE_LINK.finditer(bare):
            yield number, match.group(1)
        for match in HTML_LINK.finditer(bare):
            yield number, match.group(1)
        match = REFERENCE_DEF.match(bare)
        if match:
            yield number, match.group(1)


def check(path):
    """The broken links of one file, as messages."""
    with open(path, encoding="utf-8") as f:
        text = f.read()
    problems = []
    relative = os.path.relpath(path, ROOT)
    for number, target in links(text):
        if not target or SCHEME.match(target) or target.startswith("//"):
            continue
        file_part, _, anchor = target.partition("#")
        file_part = unquote(file_part)
        if file_part:
            resolved = os.path.normpath(os.path.join(os.path.dirname(path), file_part))
            if not os.path.exists(resolved):
                problems.append(f"{relative}:{number}: {target}: no such file")
                continue
        else:
            resolved = path
        if anchor and resolved.endswith(".md") and os.path.isfile(resolved):
            if unquote(anchor).lower() not in anchors(resolved):
                where = os.path.relpath(resolved, ROOT)
                problems.append(f"{relative}:{number}: {target}: no heading #{anchor} in {where}")
    return problems


def main(argv):
    paths = [os.path.abspath(p) for p in argv[1:]] or list(markdown_files())
    problems = []
    for path in paths:
        problems += check(path)
    for problem in problems:
        print(problem)
    sys.stdout.flush()
    print(f"{len(paths)} Markdown files checked, {len(problems)} broken links", file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
