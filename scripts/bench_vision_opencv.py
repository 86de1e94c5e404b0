#!/usr/bin/env python3
"""Contact radius: our estimator vs OpenCV on the same synthetic frames, in one run.

Generates frame pairs with a known radius (tactile example `vision_synth_frames`, which also
times our estimator per frame with a prepared reference, and the reference preparation, one
thread, release build), by default the hard set: radii 20-220 px, strong vignetting, an
illumination gradient, noise 3-8 grey levels and an edge contrast of 4-8 noise SDs. Then
runs on the very same PGM files, single-threaded:
  - OpenCV HoughCircles (HOUGH_GRADIENT) on the Gaussian-blurred |frame - reference|;
  - threshold + fitEllipse: |frame - reference| thresholded (Otsu, and a fixed 10 grey
    levels), largest contour, radius = sqrt(a b) of the fitted ellipse;
and prints, overall and per radius class, each method's time per frame, RMS / mean / max
radius error and the frames it found nothing in ("fail") side by side.

Needs: pip install opencv-python-headless numpy
Usage: scripts/bench_vision_opencv.py [--frames 100] [--seed 1] [--set hard|typical] [--out DIR]
"""
import argparse
import csv
import pathlib
import subprocess
import sys
import tempfile
import time

import cv2
import numpy as np


def load(path):
    img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if img is None:
        sys.exit(f"error: cannot read {path}")
    return img


def hough(frame, ref):
    diff = cv2.absdiff(frame, ref)
    diff = cv2.GaussianBlur(diff, (0, 0), 2.0)
    circles = cv2.HoughCircles(diff, cv2.HOUGH_GRADIENT, dp=1, minDist=400,
                               param1=30, param2=15, minRadius=10, maxRadius=240)
    if circles is None:
        return float("nan")
    return float(circles[0][0][2])


def threshold_ellipse(frame, ref, fixed=None):
    diff = cv2.absdiff(frame, ref)
    diff = cv2.GaussianBlur(diff, (5, 5), 0)
    if fixed is None:
        _, mask = cv2.threshold(diff, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    else:
        _, mask = cv2.threshold(diff, fixed, 255, cv2.THRESH_BINARY)
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not contours:
        return float("nan")
    c = max(contours, key=cv2.contourArea)
    if len(c) < 5:
        return float("nan")
    (_, _), (d1, d2), _ = cv2.fitEllipse(c)
    return 0.5 * float(np.sqrt(d1 * d2))


RADIUS_CLASSES = [(20, 60), (60, 100), (100, 140), (140, 180), (180, 221)]


def summarise(name, errors, times_ms, select=None):
    e = np.asarray(errors, dtype=float)
    t = np.asarray(times_ms, dtype=float)
    if select is not None:
        e, t = e[select], t[select]
    ok = np.isfinite(e)
    if ok.any():
        rms = float(np.sqrt(np.mean(e[ok] ** 2)))
        bias, worst = float(np.mean(e[ok])), float(np.max(np.abs(e[ok])))
    else:
        rms = bias = worst = float("nan")
    return (f"{name:<30} {np.mean(t):8.3f} {rms:9.4f} {bias:+9.4f} {worst:8.3f} "
            f"{int((~ok).sum()):4d}/{len(e)}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--set", choices=["hard", "typical"], default="hard")
    ap.add_argument("--out", type=pathlib.Path, default=None)
    args = ap.parse_args()
    root = pathlib.Path(__file__).resolve().parent.parent
    out = args.out or pathlib.Path(tempfile.mkdtemp(prefix="vision_bench_"))
    gen = subprocess.run(
        ["cargo", "run", "--quiet", "--release", "-p", "tactile", "--example",
         "vision_synth_frames", "--", str(out), str(args.frames), str(args.seed), args.set],
        cwd=root, capture_output=True, text=True)
    if gen.returncode != 0:
        sys.exit(f"error: generator failed:\n{gen.stderr}")
    print(gen.stdout.strip())
    cv2.setNumThreads(1)
    truth = list(csv.DictReader(open(out / "truth.csv")))
    ours = {int(r["index"]): r for r in csv.DictReader(open(out / "ours.csv"))}
    radii = np.asarray([float(t["radius_px"]) for t in truth])
    results = {"ours (band area + ellipse)": ([], []),
               "ours + reference preparation": ([], []),
               "OpenCV HoughCircles": ([], []),
               "OpenCV Otsu + fitEllipse": ([], []),
               "OpenCV fixed 10 + fitEllipse": ([], [])}
    for t in truth:
        i = int(t["index"])
        r_true = float(t["radius_px"])
        frame = load(out / f"frame_{i:04d}.pgm")
        ref = load(out / f"ref_{i:04d}.pgm")
        o = ours[i]
        results["ours (band area + ellipse)"][0].append(float(o["radius_px"]) - r_true)
        results["ours (band area + ellipse)"][1].append(float(o["time_us"]) / 1e3)
        results["ours + reference preparation"][0].append(float(o["radius_px"]) - r_true)
        results["ours + reference preparation"][1].append(
            (float(o["time_us"]) + float(o["prep_us"])) / 1e3)
        for name, fn in [("OpenCV HoughCircles", lambda: hough(frame, ref)),
                         ("OpenCV Otsu + fitEllipse", lambda: threshold_ellipse(frame, ref)),
                         ("OpenCV fixed 10 + fitEllipse",
                          lambda: threshold_ellipse(frame, ref, fixed=10))]:
            t0 = time.perf_counter()
            r = fn()
            dt = (time.perf_counter() - t0) * 1e3
            results[name][0].append(r - r_true)
            results[name][1].append(dt)
    header = (f"{'method':<30} {'ms/frame':>8} {'rms px':>9} {'bias px':>9} {'max px':>8} "
              f"{'fail':>6}")
    print(f"\n{len(truth)} {args.set} frames 640x480, radii 20-220 px, blur 1.5-2.5 px, "
          "vignetting, gradient, mirror")
    print(header)
    for name, (errs, times) in results.items():
        print(summarise(name, errs, times))
    for lo, hi in RADIUS_CLASSES:
        sel = (radii >= lo) & (radii < hi)
        if not sel.any():
            continue
        print(f"\nradius {lo}-{min(hi, 220)} px ({int(sel.sum())} frames)")
        for name, (errs, times) in results.items():
            print(summarise(name, errs, times, sel))
    print(f"\nframes kept in {out}")


if __name__ == "__main__":
    main()
