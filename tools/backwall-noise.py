#!/usr/bin/env python3
"""The back wall's noise in an 8-bit render of the built-in Cornell box: the mean absolute
difference of horizontally and vertically neighbouring pixels inside a rectangle of the back
wall, per channel and averaged (issue 69's measure of a "visibly clean" first image).

    python3 tools/backwall-noise.py IMAGE.png [X0 Y0 X1 Y1]

The rectangle is half-open (columns X0..X1-1, rows Y0..Y1-1); the default, x 180..300 and
y 110..180, lies inside the back wall of the 480 x 360 default render, clear of its edges,
the light's glow and the spheres. Needs numpy and Pillow.
"""
import sys

import numpy as np
from PIL import Image


def main() -> None:
    if len(sys.argv) not in (2, 6):
        sys.exit(__doc__)
    path = sys.argv[1]
    x0, y0, x1, y1 = map(int, sys.argv[2:6]) if len(sys.argv) == 6 else (180, 110, 300, 180)
    a = np.asarray(Image.open(path).convert("RGB"), dtype=np.int16)[y0:y1, x0:x1]
    if a.shape[0] < 2 or a.shape[1] < 2:
        sys.exit(f"{path}: the rectangle x {x0}..{x1}, y {y0}..{y1} has fewer than 2x2 pixels in the image")
    d = np.concatenate([np.abs(np.diff(a, axis=1)).reshape(-1, 3), np.abs(np.diff(a, axis=0)).reshape(-1, 3)])
    per = d.astype(np.float64).mean(axis=0)
    print(f"{path}: x {x0}..{x1 - 1}, y {y0}..{y1 - 1}: mean |neighbour difference| "
          f"R {per[0]:.3f} G {per[1]:.3f} B {per[2]:.3f}, mean {per.mean():.3f}")


if __name__ == "__main__":
    main()
