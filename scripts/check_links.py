#!/usr/bin/env python3
"""Checks the links of README.md, ARCHITECTURE.md and the book (docs/src).

Every relative link and image must point to an existing file, every
`#anchor` to a heading of the file it names (by mdBook's rule for heading
ids), and every `{{#include FILE[:ANCHOR]}}` to an existing file (and its
ANCHOR markers). A link from a book page must stay inside the book's
source directory (mdBook copies nothing else into the HTML) and a page it
links to must be listed in SUMMARY.md. External http(s) and mailto links
are not fetched. Python 3 standard library only.

Usage: check_links.py [--html BOOK_DIR] [ROOT]
  ROOT: the repository (default: this script's ..); with --html, also the
  book mdBook built there: every relative href and src exists and every
  #anchor is an id of its page.
Prints one line per broken link and exits 1 if there is any.
"""

import os
import re
import sys
from pathlib import Path

FENCE = re.compile(r"^ {0,3}(`{3,}|~{3,})")
HEADING = re.compile(r"^ {0,3}(#{1,6})[ \t]+(.*?)[ \t]*#*[ \t]*$")
# [text](target) and ![alt](target); the target may be <...> and have a title.
INLINE_LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*(<[^>]*>|[^)\s]+)(?:\s+\"[^\"]*\")?\s*\)")
REFERENCE_DEF = re.compile(r"^ {0,3}\[[^\]]+\]:\s*(<[^>]*>|\S+)")
HTML_LINK = re.compile(r"<(?:a|img)\s[^>]*?(?:href|src)\s*=\s*\"([^\"]*)\"", re.IGNORECASE)
INCLUDE = re.compile(r"\{\{#include\s+([^}\s]+)\s*\}\}")
CODE_SPAN = re.compile(r"(`+)(.+?)\1")
EXTERNAL = re.compile(r"^[a-zA-Z][a-zA-Z0-9+.-]*:")


def prose_lines(text):
    """(line number, line) outside fenced code blocks."""
    fence = None
    for number, line in enumerate(text.split("\n"), 1):
        m = FENCE.match(line)
        if fence is None and m:
            fence = m.group(1)[0] * len(m.group(1))
            continue
        if fence is not None:
            if line.strip().startswith(fence) and set(line.strip()) <= {fence[0]}:
                fence = None
            continue
        yield number, line


def expand_includes(path, seen=()):
    """The text of a markdown file with mdBook's {{#include}} expanded
    (whole files, or the lines between `ANCHOR: name` and `ANCHOR_END: name`)."""
    text = path.read_text(encoding="utf-8")

    def include(m):
        target, _, anchor = m.group(1).partition(":")
        file = (path.parent / target).resolve()
        if not file.is_file() or file in seen:
            return ""
        body = expand_includes(file, seen + (path.resolve(),))
        if not anchor:
            return body
        lines = body.split("\n")
        start = [i for i, l in enumerate(lines) if re.search(rf"ANCHOR:\s*{re.escape(anchor)}\b", l)]
        end = [i for i, l in enumerate(lines) if re.search(rf"ANCHOR_END:\s*{re.escape(anchor)}\b", l)]
        if not start or not end:
            return ""
        return "\n".join(l for l in lines[start[0] + 1 : end[0]] if "ANCHOR" not in l)

    return INCLUDE.sub(include, text)


def heading_text(raw):
    """The text mdBook renders for a heading: links by their text, code
    spans by their content, emphasis and HTML tags dropped."""
    explicit = re.search(r"\{#([^\s}]+)[^}]*\}\s*$", raw)
    if explicit:
        return None, explicit.group(1)
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", raw)
    text = CODE_SPAN.sub(lambda m: m.group(2).strip(), text)
    text = re.sub(r"<[^>]+>", "", text)
    text = re.sub(r"(\*\*|__|\*)", "", text)
    for entity, char in (("&amp;", "&"), ("&lt;", "<"), ("&gt;", ">"), ("&quot;", '"')):
        text = text.replace(entity, char)
    return text, None


def heading_id(text):
    """mdBook's id: lowercase; alphanumerics, `-` and `_` kept; whitespace to `-`."""
    out = []
    for ch in text.strip().lower():
        if ch.isalnum() or ch in "-_":
            out.append(ch)
        elif ch.isspace():
            out.append("-")
    return "".join(out)


_anchor_cache = {}


def anchors(path):
    """Heading ids of a markdown file, unique as mdBook makes them (-1, -2, ...)."""
    path = path.resolve()
    if path not in _anchor_cache:
        used = set()
        for _, line in prose_lines(expand_includes(path)):
            m = HEADING.match(line)
            if not m:
                continue
            text, explicit = heading_text(m.group(2))
            hid = explicit if explicit is not None else heading_id(text)
            if hid in used:
                n = 1
                while f"{hid}-{n}" in used:
                    n += 1
                hid = f"{hid}-{n}"
            used.add(hid)
        _anchor_cache[path] = used
    return _anchor_cache[path]


def links(text):
    """(line number, target) of every link, image and include in prose."""
    for number, line in prose_lines(text):
        for m in INCLUDE.finditer(line):
            yield number, m.group(1), "include"
        line = INCLUDE.sub("", line)
        code_free = CODE_SPAN.sub(lambda m: " " * len(m.group(0)), line)
        for pattern in (INLINE_LINK, REFERENCE_DEF, HTML_LINK):
            for m in pattern.finditer(code_free):
                target = m.group(1)
                if target.startswith("<") and target.endswith(">"):
                    target = target[1:-1]
                yield number, target, "link"


def summary_pages(src):
    summary = src / "SUMMARY.md"
    pages = {summary.resolve()}
    if summary.is_file():
        for _, target, _ in links(summary.read_text(encoding="utf-8")):
            pages.add((src / target.split("#")[0]).resolve())
    return pages


def check_file(path, root, src, pages):
    errors = []
    in_book = src in path.resolve().parents
    rel = path.relative_to(root)
    for number, target, kind in links(path.read_text(encoding="utf-8")):
        where = f"{rel}:{number}: {target}"
        if kind == "include":
            file_part, _, anchor = target.partition(":")
            file = (path.parent / file_part).resolve()
            if not file.is_file():
                errors.append(f"{where}: included file does not exist")
            elif anchor:
                body = file.read_text(encoding="utf-8")
                if not (re.search(rf"ANCHOR:\s*{re.escape(anchor)}\b", body)
                        and re.search(rf"ANCHOR_END:\s*{re.escape(anchor)}\b", body)):
                    errors.append(f"{where}: no ANCHOR/ANCHOR_END `{anchor}` in {file_part}")
            continue
        if EXTERNAL.match(target) or target.startswith("//"):
            continue  # http(s), mailto: not fetched
        file_part, _, anchor = target.partition("#")
        file_part = file_part.split("?")[0]
        dest = (path.parent / file_part).resolve() if file_part else path.resolve()
        if not dest.exists():
            errors.append(f"{where}: no such file")
            continue
        if in_book and src not in dest.parents and dest != src:
            errors.append(f"{where}: leaves the book's source directory (mdBook does not copy it)")
            continue
        if in_book and dest.suffix == ".md" and dest not in pages:
            errors.append(f"{where}: page not listed in SUMMARY.md (mdBook does not render it)")
            continue
        if anchor:
            if dest.suffix != ".md":
                errors.append(f"{where}: anchor into a file that is not markdown")
            elif anchor not in anchors(dest):
                errors.append(f"{where}: no heading with id `{anchor}` in {os.path.relpath(dest, root)}")
    return errors


def check_html(book):
    """The built book: every relative href and src names a file of the book,
    and every #anchor an id of the page it names (the ids mdBook made)."""
    errors = []
    ids = {}
    pages = sorted(book.rglob("*.html"))
    for page in pages:
        ids[page.resolve()] = set(re.findall(r'\sid="([^"]+)"', page.read_text(encoding="utf-8")))
    for page in pages:
        text = page.read_text(encoding="utf-8")
        for target in re.findall(r'\s(?:href|src)="([^"]*)"', text):
            if EXTERNAL.match(target) or target.startswith("//") or not target:
                continue
            file_part, _, anchor = target.partition("#")
            file_part = file_part.split("?")[0]
            dest = (page.parent / file_part).resolve() if file_part else page.resolve()
            where = f"{page.relative_to(book)}: {target}"
            if not dest.exists():
                errors.append(f"{where}: not in the built book")
            elif anchor and dest.suffix == ".html" and anchor not in ids.get(dest, ()):
                errors.append(f"{where}: no id `{anchor}` in the built page")
    return errors


def main():
    args = sys.argv[1:]
    html = None
    if len(args) >= 2 and args[0] == "--html":
        html = Path(args[1]).resolve()
        args = args[2:]
    root = Path(args[0] if args else Path(__file__).resolve().parent.parent).resolve()
    src = (root / "docs" / "src").resolve()
    files = [root / "README.md", root / "ARCHITECTURE.md"] + sorted(src.rglob("*.md"))
    pages = summary_pages(src)
    errors = []
    count = 0
    for path in files:
        if path.is_file():
            count += 1
            errors += check_file(path, root, src, pages)
    for page in sorted(src.rglob("*.md")):
        if page.resolve() not in pages:
            errors.append(f"{page.relative_to(root)}: not listed in docs/src/SUMMARY.md")
    if html is not None:
        errors += check_html(html)
    for e in errors:
        print(e)
    built = f" and the book built in {html}" if html is not None else ""
    print(f"check_links: {count} markdown files{built}, {len(errors)} broken link(s)", file=sys.stderr)
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
