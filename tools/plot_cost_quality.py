#!/usr/bin/env python3
"""What accuracy costs in time: one point per run, test PSNR against training seconds, as a plain
SVG (standard library only).

usage: plot_cost_quality.py [--metrics NAME] OUT.svg RUN[=LABEL] [RUN[=LABEL] ...]

Reads each RUN/log.csv (the last row's `seconds`: the run's wall-clock training time, as
`hashcc train` logs it; or RUN/log.csv.gz, the thinned copy committed under docs/results, which
keeps the last row) and RUN/metrics.json (or RUN/NAME with --metrics, e.g.
metrics_sim3_1000.json: what `hashcc eval` wrote, copied beside the run), and plots the
metrics' test PSNR against those seconds, labelled. Seconds are only comparable between runs
made side by side on one machine: say which in the caption.
"""
import csv
import gzip
import json
import os
import sys

from svg_axes import COLOURS, Frame


def read_point(run, metrics_name):
    log = os.path.join(run, 'log.csv')
    if not os.path.exists(log) and os.path.exists(log + '.gz'):
        log += '.gz'
    met = os.path.join(run, metrics_name)
    for path in (log, met):
        if not os.path.exists(path):
            sys.exit(f"{path}: no such file (expected a run folder with log.csv and {metrics_name})")
    with (gzip.open(log, 'rt') if log.endswith('.gz') else open(log)) as f:
        rows = list(csv.DictReader(f))
    if not rows or 'seconds' not in rows[-1]:
        sys.exit(f"{log}: expected a header with seconds and at least one row")
    with open(met) as f:
        m = json.load(f)
    if 'psnr' not in m:
        sys.exit(f"{met}: expected a 'psnr' field (written by hashcc eval)")
    return float(rows[-1]['seconds']), float(m['psnr']), int(rows[-1]['step'])


def main():
    args = sys.argv[1:]
    metrics_name = 'metrics.json'
    if len(args) >= 2 and args[0] == '--metrics':
        metrics_name, args = args[1], args[2:]
    if len(args) < 2:
        sys.exit(__doc__)
    out, specs = args[0], args[1:]
    points = []
    for spec in specs:
        run, _, label = spec.partition('=')
        s, p, steps = read_point(run, metrics_name)
        points.append((label or os.path.basename(os.path.normpath(run)), s, p, steps))
    xs = [s for _, s, _, _ in points]
    ys = [p for _, _, p, _ in points]
    pad = max(0.1, (max(ys) - min(ys)) * 0.15)
    fr = Frame(900, 420, 60, 360, 20, 45, (0.0, max(xs) * 1.1), (min(ys) - pad, max(ys) + pad))
    X, Y, W, R, T = fr.X, fr.Y, fr.W, fr.R, fr.T
    svg = fr.open('training time (s, wall clock)', 'test PSNR (dB)', y_fmt='{:.2f}')
    for i, (label, s, p, steps) in enumerate(points):
        col = COLOURS[i % len(COLOURS)]
        svg.append(f'<circle cx="{X(s):.1f}" cy="{Y(p):.1f}" r="5" fill="{col}"/>')
        svg.append(f'<text x="{X(s) + 8:.1f}" y="{Y(p) - 6:.1f}" fill="{col}">{i + 1}</text>')
        y = T + 16 * i + 8
        svg.append(f'<circle cx="{W - R + 16}" cy="{y}" r="5" fill="{col}"/>')
        svg.append(f'<text x="{W - R + 26}" y="{y + 4}">{i + 1} {label}: {p:.2f} dB, '
                   f'{s:.0f} s, {steps} steps</text>')
    fr.save(svg, out)
    print(f"wrote {out}: {len(points)} runs")


if __name__ == '__main__':
    main()
