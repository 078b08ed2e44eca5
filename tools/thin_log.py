#!/usr/bin/env python3
"""Thin a run's per-step log.csv for committing under docs/results/ (issue 50, the evidence store).

usage: thin_log.py [--check] LOG.csv [LOG.csv ...]

Writes LOG.csv.gz beside each LOG.csv (gzip, reproducible: no name, mtime 0) and deletes nothing;
`git rm` the log.csv yourself. The .gz keeps, in order:
  - the header;
  - the first and the last data row;
  - every row whose step (first column) is a multiple of 10;
  - the last 500 data rows in full, so a "train PSNR, mean of the last 500 steps" quoted in the
    docs recomputes exactly;
  - where the step column goes back (a restart logged into one file), the row before the drop
    and the row after it.
Rows are never changed. Read one with `zcat LOG.csv.gz` (or `gzip.open(path, 'rt')`).
--check: read each LOG.csv.gz back and check it against the rule above (LOG.csv must exist).
"""
import gzip
import io
import sys

EVERY = 10
TAIL = 500


def thin(text):
    lines = [l for l in text.split('\n') if l.strip()]
    header, rows = lines[0], lines[1:]
    if header.split(',')[0] != 'step':
        raise ValueError(f"first column is '{header.split(',')[0]}', expected 'step'")
    n = len(rows)
    steps = []
    for r in rows:
        s = r.split(',')[0]
        steps.append(int(s) if s.isdigit() else None)
    keep = [False] * n
    for i, s in enumerate(steps):
        if i == 0 or i == n - 1 or i >= n - TAIL or s is None or s % EVERY == 0:
            keep[i] = True
        if i > 0 and s is not None and steps[i - 1] is not None and s <= steps[i - 1]:
            keep[i - 1] = keep[i] = True  # a restart inside one log: keep both sides
    return header + '\n' + ''.join(r + '\n' for r, k in zip(rows, keep) if k)


def gz_bytes(text):
    buf = io.BytesIO()
    with gzip.GzipFile(filename='', mode='wb', compresslevel=9, fileobj=buf, mtime=0) as f:
        f.write(text.encode())
    return buf.getvalue()


def main():
    args = sys.argv[1:]
    check = bool(args) and args[0] == '--check'
    if check:
        args = args[1:]
    if not args:
        sys.exit(__doc__)
    for path in args:
        with open(path) as f:
            text = f.read()
        want = thin(text)
        if check:
            with gzip.open(path + '.gz', 'rt') as f:
                got = f.read()
            if got != want:
                sys.exit(f"{path}.gz: differs from the thinned {path}")
        else:
            with open(path + '.gz', 'wb') as f:
                f.write(gz_bytes(want))
    print(f"{len(args)} log(s) {'checked' if check else 'thinned'}")


if __name__ == '__main__':
    main()
