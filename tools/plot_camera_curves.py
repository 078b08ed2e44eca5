#!/usr/bin/env python3
"""Relative rotation error against training steps, one line per run, as a plain SVG.

usage: plot_camera_curves.py OUT.svg RUN[=LABEL] [RUN[=LABEL] ...]

Reads each RUN/camera_error.csv (written by `hashcc train` when the scene has reference
cameras: step, seconds, rel_rot_deg, …) and draws rel_rot_deg against the step, with the
do-nothing error (the value at step 0) as a dashed line. Standard library only.

Stages are drawn as one line, each after the one before it (steps counted from the first
stage's start): a run of `hashcc train --restarts K` (its RUN/stage1 … stageK, then RUN), or
runs joined by '+' (RUN1+RUN2+…, e.g. runs chained by hand with --cameras-from).
"""
import csv
import os
import sys

COLOURS = ['#1f77b4', '#d62728', '#2ca02c', '#ff7f0e', '#9467bd', '#8c564b', '#e377c2',
           '#7f7f7f', '#17becf', '#bcbd22']


def read_stages(spec):
    """One curve from the stages of a run: RUN/stage1 … stageK then RUN, or RUN1+RUN2+…."""
    runs = spec.split('+')
    if len(runs) == 1:
        k = 1
        stages = []
        while os.path.isdir(os.path.join(spec, f'stage{k}')):
            stages.append(os.path.join(spec, f'stage{k}'))
            k += 1
        runs = stages + [spec]
    curve, offset = [], 0
    for run in runs:
        c = read_curve(run)
        curve += [(s + offset, e) for s, e in c if not (curve and s == 0)]
        offset = curve[-1][0]
    return curve


def read_curve(run):
    path = os.path.join(run, 'camera_error.csv')
    if not os.path.exists(path):
        sys.exit(f"{path}: no such file (the run has no reference cameras, or is not a run)")
    with open(path) as f:
        rows = list(csv.DictReader(f))
    if not rows or 'rel_rot_deg' not in rows[0]:
        sys.exit(f"{path}: expected a header with step and rel_rot_deg")
    return [(int(r['step']), float(r['rel_rot_deg'])) for r in rows]


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    out, runs = sys.argv[1], sys.argv[2:]
    curves = []
    for spec in runs:
        run, _, label = spec.partition('=')
        curves.append((label or os.path.basename(os.path.normpath(run)), read_stages(run)))
    W, H, L, R, T, B = 720, 420, 60, 200, 20, 45
    xmax = max(s for _, c in curves for s, _ in c) or 1
    ymax = max(e for _, c in curves for _, e in c) * 1.05
    X = lambda s: L + (W - L - R) * s / xmax
    Y = lambda e: T + (H - T - B) * (1 - e / ymax)
    svg = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" '
           f'font-family="sans-serif" font-size="12">',
           f'<rect width="{W}" height="{H}" fill="white"/>']
    for k in range(6):  # y grid
        e = ymax * k / 5
        svg.append(f'<line x1="{L}" x2="{W - R}" y1="{Y(e):.1f}" y2="{Y(e):.1f}" stroke="#ddd"/>')
        svg.append(f'<text x="{L - 6}" y="{Y(e) + 4:.1f}" text-anchor="end">{e:.1f}</text>')
    for k in range(6):  # x ticks
        s = xmax * k / 5
        svg.append(f'<text x="{X(s):.1f}" y="{H - B + 16}" text-anchor="middle">{s:.0f}</text>')
    svg.append(f'<text x="{(L + W - R) / 2}" y="{H - 8}" text-anchor="middle">training step</text>')
    svg.append(f'<text x="14" y="{(T + H - B) / 2}" text-anchor="middle" '
               f'transform="rotate(-90 14 {(T + H - B) / 2})">relative rotation error (deg)</text>')
    e0 = curves[0][1][0][1]
    svg.append(f'<line x1="{L}" x2="{W - R}" y1="{Y(e0):.1f}" y2="{Y(e0):.1f}" stroke="#888" '
               f'stroke-dasharray="5,4"/>')
    svg.append(f'<text x="{W - R - 4}" y="{Y(e0) - 4:.1f}" text-anchor="end" fill="#666">'
               f'do nothing {e0:.2f}°</text>')
    for i, (label, c) in enumerate(curves):
        col = COLOURS[i % len(COLOURS)]
        pts = ' '.join(f'{X(s):.1f},{Y(e):.1f}' for s, e in c)
        svg.append(f'<polyline fill="none" stroke="{col}" stroke-width="1.6" points="{pts}"/>')
        y = T + 16 * i + 8
        svg.append(f'<line x1="{W - R + 10}" x2="{W - R + 28}" y1="{y}" y2="{y}" stroke="{col}" '
                   f'stroke-width="2"/>')
        svg.append(f'<text x="{W - R + 32}" y="{y + 4}">{label} ({c[-1][1]:.2f}°)</text>')
    svg.append(f'<line x1="{L}" x2="{L}" y1="{T}" y2="{H - B}" stroke="black"/>')
    svg.append(f'<line x1="{L}" x2="{W - R}" y1="{H - B}" y2="{H - B}" stroke="black"/>')
    svg.append('</svg>')
    with open(out, 'w') as f:
        f.write('\n'.join(svg) + '\n')
    print(f"wrote {out}: {len(curves)} runs, steps 0..{xmax}")


if __name__ == '__main__':
    main()
