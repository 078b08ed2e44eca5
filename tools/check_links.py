#!/usr/bin/env python3
"""Check the relative links of the repository's markdown: README.md and docs/**/*.md.

usage: check_links.py [ROOT]   (ROOT: the repository, default: this file's parent's parent)

For every [text](target) and ![alt](target) whose target is not a URL: the file or folder must
exist, and a #anchor into a .md file must match one of its headings (GitHub's slugs: lower case,
punctuation dropped, spaces to '-', repeats numbered -1, -2, …). Links inside code spans and
fenced blocks are skipped. Prints each broken link as FILE:LINE: TARGET (why); exit 1 if any.
"""
import os
import re
import sys
from urllib.parse import unquote

LINK = re.compile(r'!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+"[^"]*")?\s*\)')
HEADING = re.compile(r'^\s{0,3}(#{1,6})\s+(.*?)\s*#*\s*$')


def strip_code(line):
    return re.sub(r'`[^`]*`', '', line)


def md_lines(path):
    """(line number, text) of a markdown file outside fenced code blocks."""
    fence = None
    with open(path, encoding='utf-8') as f:
        for n, line in enumerate(f, 1):
            m = re.match(r'^\s*(```|~~~)', line)
            if m:
                fence = None if fence == m.group(1) else (fence or m.group(1))
                continue
            if fence is None:
                yield n, line.rstrip('\n')


def slug(text):
    text = re.sub(r'!?\[([^\]]*)\]\([^)]*\)', r'\1', text)  # links: their text
    text = re.sub(r'<[^>]+>', '', text)                      # inline html
    text = text.replace('`', '').replace('*', '')
    text = re.sub(r'(?<!\w)_+|_+(?!\w)', '', text)           # _emphasis_, not snake_case
    text = text.strip().lower()
    text = re.sub(r'[^\w\- ]', '', text)
    return text.replace(' ', '-')


_anchors = {}


def anchors(path):
    if path not in _anchors:
        seen, out = {}, set()
        for _, line in md_lines(path):
            m = HEADING.match(line)
            if not m:
                continue
            s = slug(m.group(2))
            k = seen.get(s, 0)
            out.add(s if k == 0 else f'{s}-{k}')
            seen[s] = k + 1
            for a in re.findall(r'<a\s+(?:name|id)="([^"]+)"', line):
                out.add(a)
        for _, line in md_lines(path):
            for a in re.findall(r'<a\s+(?:name|id)="([^"]+)"', line):
                out.add(a)
        _anchors[path] = out
    return _anchors[path]


def md_files(root):
    yield os.path.join(root, 'README.md')
    for d, _, files in os.walk(os.path.join(root, 'docs')):
        for f in sorted(files):
            if f.endswith('.md'):
                yield os.path.join(d, f)


def main():
    root = os.path.abspath(sys.argv[1] if len(sys.argv) > 1 else
                           os.path.join(os.path.dirname(os.path.abspath(__file__)), '..'))
    bad = checked = 0
    for path in md_files(root):
        for n, line in md_lines(path):
            for target in LINK.findall(strip_code(line)):
                if re.match(r'^[a-z][a-z0-9+.-]*:', target, re.I):
                    continue  # http:, https:, mailto:
                checked += 1
                file_part, _, anchor = target.partition('#')
                file_part = unquote(file_part)
                dest = path if not file_part else os.path.normpath(
                    os.path.join(root, file_part.lstrip('/')) if file_part.startswith('/')
                    else os.path.join(os.path.dirname(path), file_part))
                why = None
                if not os.path.exists(dest):
                    why = 'no such file'
                elif anchor and dest.endswith('.md') and os.path.isfile(dest):
                    if unquote(anchor).lower() not in anchors(dest):
                        why = 'no such heading'
                if why:
                    bad += 1
                    print(f'{os.path.relpath(path, root)}:{n}: {target} ({why})')
    print(f'{checked} relative links checked, {bad} broken')
    sys.exit(1 if bad else 0)


if __name__ == '__main__':
    main()
