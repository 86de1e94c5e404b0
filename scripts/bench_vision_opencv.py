#!/usr/bin/env python3
"""Contact radius: our estimator vs OpenCV on the same synthetic frames, in one run.

Generates frame pairs with a known radius (host example `vision_synth_frames`, which also
times our estimator: reference preparation + measurement, one thread, release build), then
runs on the very same PGM files, single-threaded:
  - OpenCV HoughCircles (HOUGH_GRADIENT) on the Gaussian-blurred |frame - reference|;
  - threshold + fitEllipse: |frame - reference| thresholded (Otsu, and a fixed 10 grey
    levels), largest contour, radius = sqrt(a b) of the fitted ellipse;
and prints time per frame, RMS / mean / max radius error and the mean error per contrast
level side by side.

Needs: pip install opencv-python-headless numpy
Usage: scripts/bench_vision_opencv.py [--frames 60] [--seed 1] [--out DIR]
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
                               param1=30, param2=15, minRadius=30, maxRadius=230)
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


def summarise(name, errors, times_ms, contrasts):
    e = np.asarray(errors, dtype=float)
    ok = np.isfinite(e)
    rms = float(np.sqrt(np.mean(e[ok] ** 2))) if ok.any() else float("nan")
    by_c = []
    for c in sorted(set(abs(c) for c in contrasts)):
        sel = ok & (np.abs(np.asarray(contrasts)) == c)
        by_c.append(f"{np.mean(e[sel]):+7.3f}" if sel.any() else "    n/a")
    return (f"{name:<26} {np.mean(times_ms):8.3f} {rms:9.4f} {np.mean(e[ok]):+9.4f} "
            f"{np.max(np.abs(e[ok])):8.3f} {int((~ok).sum()):5d}   " + " ".join(by_c))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", type=pathlib.Path, default=None)
    args = ap.parse_args()
    root = pathlib.Path(__file__).resolve().parent.parent
    out = args.out or pathlib.Path(tempfile.mkdtemp(prefix="vision_bench_"))
    gen = subprocess.run(
        ["cargo", "run", "--quiet", "--release", "-p", "host", "--example",
         "vision_synth_frames", "--", str(out), str(args.frames), str(args.seed)],
        cwd=root, capture_output=True, text=True)
    if gen.returncode != 0:
        sys.exit(f"error: generator failed:\n{gen.stderr}")
    print(gen.stdout.strip())
    cv2.setNumThreads(1)
    truth = list(csv.DictReader(open(out / "truth.csv")))
    ours = {int(r["index"]): r for r in csv.DictReader(open(out / "ours.csv"))}
    contrasts = [float(t["contrast"]) for t in truth]
    results = {"ours (band area + ellipse)": ([], []),
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
        for name, fn in [("OpenCV HoughCircles", lambda: hough(frame, ref)),
                         ("OpenCV Otsu + fitEllipse", lambda: threshold_ellipse(frame, ref)),
                         ("OpenCV fixed 10 + fitEllipse",
                          lambda: threshold_ellipse(frame, ref, fixed=10))]:
            t0 = time.perf_counter()
            r = fn()
            dt = (time.perf_counter() - t0) * 1e3
            results[name][0].append(r - r_true)
            results[name][1].append(dt)
    levels = " ".join(f"{int(c):>7d}" for c in sorted(set(abs(c) for c in contrasts)))
    print(f"\n{len(truth)} frames 640x480, blur 1.5-2.5 px, noise 2-6, vignetting, gradient, mirror")
    print(f"{'method':<26} {'ms/frame':>8} {'rms px':>9} {'bias px':>9} {'max px':>8} {'fail':>5}"
          f"   mean error by |contrast| {levels}")
    for name, (errs, times) in results.items():
        print(summarise(name, errs, times, contrasts))
    print(f"\nframes kept in {out}")


if __name__ == "__main__":
    main()
