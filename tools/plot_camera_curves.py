#!/usr/bin/env python3
"""A camera_error.csv column (relative rotation error by default, or ΔR, fx, fy) against training
steps, one line per run, as a plain SVG.

usage: plot_camera_curves.py [--column COL] [--x step|seconds] OUT.svg RUN[=LABEL] [RUN[=LABEL] ...]

Reads each RUN/camera_error.csv (written by `hashcc train` when the scene has reference
cameras: step, seconds, rel_rot_deg, sim3_dR_deg, fx, fy, ref_focal) and draws a column against
the step: rel_rot_deg (the default) with the do-nothing error (the value at step 0) as a dashed
line, or sim3_dR_deg, or fx / fy with the reference focal (ref_focal) as the dashed line.
`--x seconds` draws it against training seconds instead of steps: runs of different speeds (threads,
machines, models) compared by what each minute bought. Standard library only.

Stages are drawn as one line, each after the one before it (steps counted from the first
stage's start, or seconds from it): a run of `hashcc train --restarts K` (its RUN/stage1 … stageK, then RUN), or
runs joined by '+' (RUN1+RUN2+…, e.g. runs chained by hand with --cameras-from).
"""
import csv
import os
import sys

from svg_axes import COLOURS, Frame

COLUMNS = {  # column: axis title, unit, the dashed line's label, its value from a row
    'rel_rot_deg': ('relative rotation error (deg)', '°', 'do nothing', None),
    'sim3_dR_deg': ('Sim(3) rotation error ΔR (deg)', '°', None, None),
    'fx': ('focal fx (px)', ' px', 'reference', 'ref_focal'),
    'fy': ('focal fy (px)', ' px', 'reference', 'ref_focal'),
}
COLUMN = 'rel_rot_deg'
X_COLUMN = 'step'  # or 'seconds'


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
    if not rows or COLUMN not in rows[0]:
        sys.exit(f"{path}: expected a header with step and {COLUMN}")
    # Sim(3) columns are empty at step 0 (identity cameras: no alignment to measure): skipped.
    return [(float(r[X_COLUMN]), float(r[COLUMN])) for r in rows if r[COLUMN] != '']


def reference_value(spec):
    """The dashed line: the run's ref_focal for a focal column, else the first value (step 0)."""
    ref_col = COLUMNS[COLUMN][3]
    if ref_col is None:
        return None
    run = spec.split('+')[0]
    with open(os.path.join(run, 'camera_error.csv')) as f:
        return float(next(csv.DictReader(f))[ref_col])


def main():
    global COLUMN, X_COLUMN
    args = sys.argv[1:]
    while len(args) >= 2 and args[0] in ('--column', '--x'):
        if args[0] == '--column':
            COLUMN = args[1]
            if COLUMN not in COLUMNS:
                sys.exit(f"--column {COLUMN}: expected one of {', '.join(COLUMNS)}")
        else:
            X_COLUMN = args[1]
            if X_COLUMN not in ('step', 'seconds'):
                sys.exit(f"--x {X_COLUMN}: expected step or seconds")
        args = args[2:]
    if len(args) < 2:
        sys.exit(__doc__)
    out, runs = args[0], args[1:]
    title, unit, line_label, _ = COLUMNS[COLUMN]
    curves = []
    for spec in runs:
        run, _, label = spec.partition('=')
        curves.append((label or os.path.basename(os.path.normpath(run)), read_stages(run)))
    W, H, L, R, T, B = 720, 420, 60, 200, 20, 45
    xmax = max(s for _, c in curves for s, _ in c) or 1
    # The dashed line: the do-nothing error (the first run's step 0) or the reference focal.
    ref = reference_value(runs[0].partition('=')[0])
    e0 = ref if ref is not None else curves[0][1][0][1]
    values = [e for _, c in curves for _, e in c] + ([e0] if line_label else [])
    ymax = max(values) * 1.05
    ymin = 0.0 if COLUMN.endswith('_deg') else min(values) * 0.95
    fr = Frame(W, H, L, R, T, B, (0, xmax), (ymin, ymax))
    X, Y = fr.X, fr.Y
    svg = fr.open('training step' if X_COLUMN == 'step' else 'training seconds', title, y_fmt='{:.1f}' if ymax < 100 else '{:.0f}')
    if line_label:
        svg.append(f'<line x1="{L}" x2="{W - R}" y1="{Y(e0):.1f}" y2="{Y(e0):.1f}" stroke="#888" '
                   f'stroke-dasharray="5,4"/>')
        svg.append(f'<text x="{W - R - 4}" y="{Y(e0) - 4:.1f}" text-anchor="end" fill="#666">'
                   f'{line_label} {e0:.2f}{unit}</text>')
    for i, (label, c) in enumerate(curves):
        col = COLOURS[i % len(COLOURS)]
        pts = ' '.join(f'{X(s):.1f},{Y(e):.1f}' for s, e in c)
        svg.append(f'<polyline fill="none" stroke="{col}" stroke-width="1.6" points="{pts}"/>')
        y = T + 16 * i + 8
        svg.append(f'<line x1="{W - R + 10}" x2="{W - R + 28}" y1="{y}" y2="{y}" stroke="{col}" '
                   f'stroke-width="2"/>')
        svg.append(f'<text x="{W - R + 32}" y="{y + 4}">{label} ({c[-1][1]:.2f}{unit})</text>')
    fr.save(svg, out)
    print(f"wrote {out}: {len(curves)} runs, {X_COLUMN} 0..{xmax:g}")


if __name__ == '__main__':
    main()
