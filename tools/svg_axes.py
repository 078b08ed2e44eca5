"""The plain-SVG frame the plot tools share (standard library only): a white page, a y grid
with tick labels, x tick labels, the two axis titles, and the axes drawn last, over the data.

    frame = Frame(W, H, L, R, T, B, (xmin, xmax), (ymin, ymax))
    svg = frame.open(x_title, y_title, y_fmt='{:.1f}', x_fmt='{:.0f}')
    svg.append(...)                 # the data, placed with frame.X(x), frame.Y(y)
    frame.save(svg, out)            # the axes, </svg>, written to out
"""

COLOURS = ['#1f77b4', '#d62728', '#2ca02c', '#ff7f0e', '#9467bd', '#8c564b', '#e377c2',
           '#7f7f7f', '#17becf', '#bcbd22']


class Frame:
    """A plot area inside a W × H page with margins L, R (legend room), T, B."""

    def __init__(self, W, H, L, R, T, B, xrange, yrange):
        self.W, self.H, self.L, self.R, self.T, self.B = W, H, L, R, T, B
        (self.xmin, self.xmax), (self.ymin, self.ymax) = xrange, yrange

    def X(self, x):
        return self.L + (self.W - self.L - self.R) * (x - self.xmin) / (self.xmax - self.xmin)

    def Y(self, y):
        return self.T + (self.H - self.T - self.B) * (1 - (y - self.ymin) / (self.ymax - self.ymin))

    def open(self, x_title, y_title, y_fmt='{:.1f}', x_fmt='{:.0f}'):
        W, H, L, R, T, B = self.W, self.H, self.L, self.R, self.T, self.B
        svg = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" '
               f'font-family="sans-serif" font-size="12">',
               f'<rect width="{W}" height="{H}" fill="white"/>']
        for k in range(6):  # y grid
            y = self.ymin + (self.ymax - self.ymin) * k / 5
            svg.append(f'<line x1="{L}" x2="{W - R}" y1="{self.Y(y):.1f}" y2="{self.Y(y):.1f}" '
                       f'stroke="#ddd"/>')
            svg.append(f'<text x="{L - 6}" y="{self.Y(y) + 4:.1f}" text-anchor="end">'
                       f'{y_fmt.format(y)}</text>')
        for k in range(6):  # x ticks
            x = self.xmin + (self.xmax - self.xmin) * k / 5
            svg.append(f'<text x="{self.X(x):.1f}" y="{H - B + 16}" text-anchor="middle">'
                       f'{x_fmt.format(x)}</text>')
        svg.append(f'<text x="{(L + W - R) / 2}" y="{H - 8}" text-anchor="middle">{x_title}</text>')
        svg.append(f'<text x="14" y="{(T + H - B) / 2}" text-anchor="middle" '
                   f'transform="rotate(-90 14 {(T + H - B) / 2})">{y_title}</text>')
        return svg

    def save(self, svg, out):
        W, H, L, R, T, B = self.W, self.H, self.L, self.R, self.T, self.B
        svg.append(f'<line x1="{L}" x2="{L}" y1="{T}" y2="{H - B}" stroke="black"/>')
        svg.append(f'<line x1="{L}" x2="{W - R}" y1="{H - B}" y2="{H - B}" stroke="black"/>')
        svg.append('</svg>')
        with open(out, 'w') as f:
            f.write('\n'.join(svg) + '\n')
