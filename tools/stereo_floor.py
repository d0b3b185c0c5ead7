#!/usr/bin/env python3
"""How well the linear stereo noise model covers the range error of the points a matcher
reports, by band of reported range: Monte Carlo over ground seen by one camera row per
disparity step (true disparities uniform over the ground's extent), Gaussian disparity
noise, and the matcher's disparity floor.

    .venv/bin/python tools/stereo_floor.py FB_PX_M SIGMA_D_PX MIN_D_PX NEAR_M FAR_M

FB_PX_M is the disparity image's focal length times the baseline (px·m), SIGMA_D_PX the
disparity noise, MIN_D_PX the smallest disparity reported, NEAR_M..FAR_M the ground's
extent. Prints, per band of reported range, the share of points whose range error lies
within 1 and 3 linear σ (σ_z = z²·σ_d/(f·B) at the reported z) and the RMS error over the
RMS σ.
"""
import sys

import numpy as np


def main(fb, sd, dmin, near, far):
    rng = np.random.default_rng(1)
    d = rng.uniform(fb / far, fb / near, 2_000_000)
    dm = d + rng.normal(0.0, sd, d.size)
    ok = dm >= dmin
    z, zm = fb / d[ok], fb / dm[ok]
    print("| reported range (m) | points | within 1σ | within 3σ | RMS error / RMS σ |")
    print("| --- | ---: | ---: | ---: | ---: |")
    for lo, hi in [(5, 10), (10, 20), (20, 30)]:
        k = (zm >= lo) & (zm < hi)
        if not k.any():
            continue
        e, s = zm[k] - z[k], zm[k] ** 2 * sd / fb
        print(f"| {lo}–{hi} | {k.sum()} | {100 * np.mean(np.abs(e) <= s):.1f} % | "
              f"{100 * np.mean(np.abs(e) <= 3 * s):.1f} % | "
              f"{np.sqrt(np.mean(e ** 2)) / np.sqrt(np.mean(s ** 2)):.2f} |")


if __name__ == "__main__":
    if len(sys.argv) != 6:
        sys.exit(__doc__)
    main(*map(float, sys.argv[1:]))
