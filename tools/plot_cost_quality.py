#!/usr/bin/env python3
"""What accuracy costs in time: one point per run, test PSNR against training seconds, as a plain
SVG (standard library only).

usage: plot_cost_quality.py [--metrics NAME] OUT.svg RUN[=LABEL] [RUN[=LABEL] ...]

Reads each RUN/log.csv (the last row's `seconds`: the run's wall-clock training time, as
`hashcc train` logs it) and RUN/metrics.json (or RUN/NAME with --metrics, e.g.
metrics_sim3_1000.json: what `hashcc eval` wrote, copied beside the run), and plots the
metrics' test PSNR against those seconds, labelled. Seconds are only comparable between runs
made side by side on one machine: say which in the caption.
"""
import csv
import json
import os
import sys

COLOURS = ['#1f77b4', '#d62728', '#2ca02c', '#ff7f0e', '#9467bd', '#8c564b', '#e377c2',
           '#7f7f7f', '#17becf', '#bcbd22']


def read_point(run, metrics_name):
    log = os.path.join(run, 'log.csv')
    met = os.path.join(run, metrics_name)
    for path in (log, met):
        if not os.path.exists(path):
            sys.exit(f"{path}: no such file (expected a run folder with log.csv and {metrics_name})")
    with open(log) as f:
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
    W, H, L, R, T, B = 900, 420, 60, 360, 20, 45
    xs = [s for _, s, _, _ in points]
    ys = [p for _, _, p, _ in points]
    xmin, xmax = 0.0, max(xs) * 1.1
    pad = max(0.1, (max(ys) - min(ys)) * 0.15)
    ymin, ymax = min(ys) - pad, max(ys) + pad
    X = lambda s: L + (W - L - R) * (s - xmin) / (xmax - xmin)
    Y = lambda p: T + (H - T - B) * (1 - (p - ymin) / (ymax - ymin))
    svg = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" '
           f'font-family="sans-serif" font-size="12">',
           f'<rect width="{W}" height="{H}" fill="white"/>']
    for k in range(6):  # y grid
        p = ymin + (ymax - ymin) * k / 5
        svg.append(f'<line x1="{L}" x2="{W - R}" y1="{Y(p):.1f}" y2="{Y(p):.1f}" stroke="#ddd"/>')
        svg.append(f'<text x="{L - 6}" y="{Y(p) + 4:.1f}" text-anchor="end">{p:.2f}</text>')
    for k in range(6):  # x ticks
        s = xmin + (xmax - xmin) * k / 5
        svg.append(f'<text x="{X(s):.1f}" y="{H - B + 16}" text-anchor="middle">{s:.0f}</text>')
    svg.append(f'<text x="{(L + W - R) / 2}" y="{H - 8}" text-anchor="middle">'
               f'training time (s, wall clock)</text>')
    svg.append(f'<text x="14" y="{(T + H - B) / 2}" text-anchor="middle" '
               f'transform="rotate(-90 14 {(T + H - B) / 2})">test PSNR (dB)</text>')
    for i, (label, s, p, steps) in enumerate(points):
        col = COLOURS[i % len(COLOURS)]
        svg.append(f'<circle cx="{X(s):.1f}" cy="{Y(p):.1f}" r="5" fill="{col}"/>')
        svg.append(f'<text x="{X(s) + 8:.1f}" y="{Y(p) - 6:.1f}" fill="{col}">{i + 1}</text>')
        y = T + 16 * i + 8
        svg.append(f'<circle cx="{W - R + 16}" cy="{y}" r="5" fill="{col}"/>')
        svg.append(f'<text x="{W - R + 26}" y="{y + 4}">{i + 1} {label}: {p:.2f} dB, '
                   f'{s:.0f} s, {steps} steps</text>')
    svg.append(f'<line x1="{L}" x2="{L}" y1="{T}" y2="{H - B}" stroke="black"/>')
    svg.append(f'<line x1="{L}" x2="{W - R}" y1="{H - B}" y2="{H - B}" stroke="black"/>')
    svg.append('</svg>')
    with open(out, 'w') as f:
        f.write('\n'.join(svg) + '\n')
    print(f"wrote {out}: {len(points)} runs")


if __name__ == '__main__':
    main()
