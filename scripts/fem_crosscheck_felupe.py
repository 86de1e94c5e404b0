#!/usr/bin/env python3
"""Independent check of fem-core's rigid-plate curves with felupe (not part of CI).

The probe's shell (hemisphere R1 = 5 mm, wall 0.4 mm, cylindrical skirt 4 mm clamped on its
inner surface; E1 = 2300 kPa, nu1 = 0.49) is modelled in felupe as an axisymmetric mixed
(u, p, J) nearly-incompressible neo-Hookean solid (Q1/P0/P0, Hu-Washizu
`ThreeFieldVariation`), inflated by a follower pressure on its inner hemispherical surface
(`SolidBodyPressure`, normal force per deformed area), then pressed by a rigid frictionless
plane (`ContactRigidPlane`) that moves towards the tube by h. felupe's axisymmetric frame
is (z, r). Outputs per depth: the contact radius a (linear extrapolation of g^(2/3) from
the first two open outer-surface nodes, the (r - a)^(3/2) gap law), the load P (the plane's
reaction) and u_s (inner apex displacement relative to the tube, zero after inflation).
Every case is solved on a sequence of meshes (elements along the arc and through the wall
doubled each time), so felupe's own mesh convergence is printed next to fem-core's curves
(`tactile fem curve --modulus 1e7 --pressure P --depth 1.7 --steps 34`, on the production
mesh and with `--edge-band`). Then, side by side on one core, each solver's time per curve
and its largest difference in a from the edge band's a (converged along the surfaces
and, with eight elements, through the wall).

Usage: scripts/fem_crosscheck_felupe.sh [--pressures 0,6,15] [--levels 40,80,160,320]
Units: mm, kPa, mN (printed loads in N).
"""

import argparse
import math
import os
import re
import subprocess
import sys
import time
import warnings

import numpy as np

# a Newton attempt that fails (it is then cut) warns of NaNs and singular matrices
warnings.filterwarnings("ignore", category=RuntimeWarning)
try:
    from scipy.sparse.linalg import MatrixRankWarning

    warnings.filterwarnings("ignore", category=MatrixRankWarning)
except ImportError:
    pass

try:
    import felupe as fem
except ImportError:  # the wrapper installs it
    sys.exit("felupe is not installed: run scripts/fem_crosscheck_felupe.sh")

R_OUT, WALL, SKIRT = 5.0, 0.4, 4.0
R_IN = R_OUT - WALL
E1, NU1 = 2300.0, 0.49
DEPTHS = [0.2, 0.5, 0.8, 1.1, 1.4, 1.7]


def shell_mesh(n_arc, n_thick):
    n_skirt = max(1, round(n_arc * SKIRT / (0.5 * math.pi * (R_OUT - 0.5 * WALL)) / 3))
    n1, n2 = n_arc + n_skirt, n_thick
    rect = fem.mesh.Rectangle(n=(n1 + 1, n2 + 1))
    x, y = rect.points[:, 0], rect.points[:, 1]
    i = np.rint(x * n1).astype(int)
    t = R_IN + WALL * y  # felupe's axisymmetric frame is (z, r): keeps the Jacobian positive
    phi = 0.5 * math.pi * np.minimum(i, n_arc) / n_arc
    r = np.where(i <= n_arc, t * np.sin(phi), t)
    z = np.where(i <= n_arc, -t * np.cos(phi), SKIRT * (i - n_arc) / n_skirt)
    points = np.column_stack([z, r])
    points = np.vstack([points, [-R_OUT - 1.0, 0.0]])
    mesh = fem.Mesh(points, rect.cells, "quad")
    inner = np.isclose(t, R_IN)
    sets = {
        "axis": np.flatnonzero(np.isclose(points[:-1, 1], 0.0)),
        "clamp": np.flatnonzero(inner & (i >= n_arc)),
        "inner_arc": np.append(inner & (i <= n_arc), False),
        "outer_arc": np.flatnonzero(np.isclose(t, R_OUT) & (i <= n_arc)),
        "inner_apex": int(np.flatnonzero(inner & (i == 0))[0]),
        "outer_apex": int(np.flatnonzero(np.isclose(t, R_OUT) & (i == 0))[0]),
        "centre": len(points) - 1,
    }
    return mesh, sets


def solve(p_air, n_arc, n_thick, multiplier=10.0, steps_per_mm=20, verbose=False):
    """Stage 1 (inflation) and stage 2 (the plane moves by h); rows (h, a, P_N, u_s)."""
    mesh, sets = shell_mesh(n_arc, n_thick)
    region = fem.RegionQuad(mesh)
    field = fem.FieldsMixed(region, n=3, axisymmetric=True)
    mu, bulk = E1 / (2 * (1 + NU1)), E1 / (3 * (1 - 2 * NU1))
    solid = fem.SolidBody(fem.ThreeFieldVariation(fem.NeoHooke(mu=mu, bulk=bulk)), field)
    region_p = fem.RegionQuadBoundary(mesh, mask=sets["inner_arc"], ensure_3d=True)
    field_p = fem.FieldContainer([fem.FieldAxisymmetric(region_p, dim=2)])
    field_p.link(field)
    pressure = fem.SolidBodyPressure(field_p, pressure=0.0)
    u = field[0]
    idx = np.arange(mesh.npoints)
    plate = fem.Boundary(u, mask=np.isin(idx, [sets["centre"]]))
    bounds = {
        "axis": fem.Boundary(u, mask=np.isin(idx, sets["axis"]), skip=(1, 0)),
        "clamp": fem.Boundary(u, mask=np.isin(idx, sets["clamp"])),
        "plate": plate,
    }

    def newton(items):
        dof0, dof1 = fem.dof.partition(field, bounds)
        ext0 = fem.dof.apply(field, bounds, dof0)
        return fem.newtonraphson(items=items, x0=field, dof1=dof1, dof0=dof0, ext0=ext0, verbose=0, tol=1e-8, maxiter=40)

    for p in np.linspace(0.0, p_air, 4)[1:]:
        pressure.update(p)
        res = newton([solid, pressure])
    x = mesh.points + u.values
    if verbose:
        clamp_force = fem.tools.force(field, res.fun, bounds["clamp"]) if p_air > 0 else None
        print("  stage 1: outer apex uz", u.values[sets["outer_apex"], 0], "clamp force", clamp_force,
              "p pi R_in^2 =", p_air * math.pi * R_IN**2)
    contact = fem.ContactRigidPlane(field, points=sets["outer_arc"], centerpoint=sets["centre"],
                                    normal=[1.0, 0.0], items=[solid], multiplier=multiplier)
    z_apex_outer = x[sets["outer_apex"], 0]
    apex0 = u.values[sets["inner_apex"], 0]
    start = z_apex_outer - mesh.points[sets["centre"], 0]
    out = []
    n = int(round(max(DEPTHS) * steps_per_mm))

    def advance(h_from, h_to, depth=0):
        # the plane's step from h_from to h_to, halved on failure (at most 6 times)
        checkpoint = field.checkpoint()
        try:
            plate.update([start + h_to, 0.0])
            res = newton([solid, pressure, contact])
            if not res.success:
                raise RuntimeError(f"no convergence at h = {h_to:.4f} mm")
            return res
        except Exception:
            if depth >= 6:
                raise
            field.restore(checkpoint)
            mid = 0.5 * (h_from + h_to)
            advance(h_from, mid, depth + 1)
            return advance(mid, h_to, depth + 1)

    h_prev = 0.0
    for k in range(0, n + 1):
        h = max(DEPTHS) * k / n
        try:
            res = advance(h_prev, h)
        except Exception:  # a limit point (the unpressurised shell snaps through)
            print(f"  felupe {n_arc}: no equilibrium found beyond h = {h_prev:.4f} mm", flush=True)
            break
        h_prev = h
        if any(abs(h - d) < 1e-9 for d in DEPTHS):
            x = mesh.points + u.values
            z_plane = x[sets["centre"], 0]
            force = fem.tools.force(field, res.fun, plate)
            g = x[sets["outer_arc"], 0] - z_plane
            a = contact_radius(x[sets["outer_arc"]][:, 1], g)
            out.append((h, a, 1e-3 * abs(force[0]), u.values[sets["inner_apex"], 0] - apex0))
    return out


def contact_radius(r, g):
    """First-open-pair g^(2/3) extrapolation over the outer nodes (r ascending)."""
    order = np.argsort(r)
    r, g = r[order], g[order]
    closed = np.flatnonzero(g <= 0.0)
    if len(closed) == 0:
        return 0.0
    j = closed[-1] + 1
    if j + 1 >= len(r):
        return float(r[closed[-1]])
    s0, s1 = g[j] ** (2 / 3), g[j + 1] ** (2 / 3)
    d = s0 / (s1 - s0) if s1 > s0 else 0.0
    return float(max(r[j] - d * (r[j + 1] - r[j]), r[closed[-1]]))


def femcore(p_air, edge_band=False):
    """fem-core's curve at the same depths (34 steps to 1.7 mm, E2 = 1e7 kPa: rigid), on the
    production mesh or with the band of fine elements at the contact edge; rows by h and the
    solve's wall time (s, one core, the solver's own figure)."""
    target = os.environ.get("CARGO_TARGET_DIR", "target")
    exe = os.path.join(target, "release", "tactile")
    out = os.path.join(target, "felupe-crosscheck-femcore.csv")
    cmd = [exe, "fem", "curve", "--modulus", "1e7", "--pressure", str(p_air), "--depth", "1.7",
           "--steps", "34", "--out", out] + (["--edge-band"] if edge_band else [])
    env = dict(os.environ, RAYON_NUM_THREADS="1")
    text = subprocess.run(cmd, check=True, capture_output=True, text=True, env=env)
    seconds = float(re.search(r"steps, ([0-9.]+) s\)", text.stdout + text.stderr).group(1))
    rows = {}
    with open(out) as f:
        for line in f:
            if line.startswith("#") or line.startswith("u_s_mm"):
                continue
            us, a, load, _p, _phase, h = line.split(",")[:6]
            rows[round(float(h), 4)] = (float(a), float(load), float(us))
    return rows, seconds


def speed_table(p_air, levels, res, times, production, band):
    """Time per curve against the largest difference in a from the converged reference (the
    fem-core band) over the depths every solver reached."""
    (ref, t_band), (prod, t_prod) = band, production
    print(f"  speed at {p_air:g} kPa (one core; a against fem-core's edge band):")
    print("    solver              time s   largest |a - a_band| um, largest in % of a, depths compared")

    def err(rows):
        d = [(abs(a - ref[round(h, 4)][0]) * 1e3, abs(a / ref[round(h, 4)][0] - 1) * 100)
             for h, a in rows if round(h, 4) in ref]
        return ((max(v[0] for v in d), max(v[1] for v in d)), len(d)) if d else (None, 0)

    for n in levels:
        (e, n_d) = err([(r[0], r[1]) for r in res[n]])
        es = f"{e[0]:7.1f}, {e[1]:.2f} %, {n_d}" if e else "   -"
        print(f"    felupe {n:<12d} {times[n]:7.1f}   {es}")
    (e, n_d) = err([(h, v[0]) for h, v in prod.items() if any(abs(h - d) < 1e-9 for d in DEPTHS)])
    print(f"    fem-core production {t_prod:7.1f}   {e[0]:7.1f}, {e[1]:.2f} %, {n_d}")
    print(f"    fem-core edge band  {t_band:7.1f}   (the reference)")
    finest = levels[-1]
    print(f"    felupe {finest} / fem-core edge band: {times[finest] / t_band:.1f} times the time")


def main():
    ap = argparse.ArgumentParser(description="felupe cross-check of fem-core's rigid-plate curves")
    ap.add_argument("--pressures", default="0,6,15")
    ap.add_argument("--levels", default="40,80,160", help="Q1 elements along the arc")
    ap.add_argument("--wall", type=int, default=2, help="elements through the wall at 40 along the arc")
    ap.add_argument("--multiplier", type=float, default=10.0, help="contact penalty scale")
    ap.add_argument("--no-femcore", action="store_true")
    args = ap.parse_args()
    levels = [int(v) for v in args.levels.split(",")]
    if not args.no_femcore:
        subprocess.run(["cargo", "build", "-q", "--release", "-p", "tactile"], check=True)
    for p_air in (float(v) for v in args.pressures.split(",")):
        print(f"p_air = {p_air:g} kPa, rigid plate, frictionless")
        production = band = None
        if not args.no_femcore:
            production, band = femcore(p_air), femcore(p_air, edge_band=True)
        res, times = {}, {}
        for n in levels:
            start = time.perf_counter()
            res[n] = solve(p_air, n, max(1, args.wall * n // 40), args.multiplier)
            times[n] = time.perf_counter() - start
        print("  h mm | " + " | ".join(f"felupe {n}: a mm  P N  u_s mm" for n in levels)
              + " | fem-core: a mm  P N  u_s mm | fem-core band: a mm  P N  u_s mm")
        for i, h in enumerate(DEPTHS):
            cols = [
                f"{res[n][i][1]:.4f} {res[n][i][2]:.4f} {res[n][i][3]:.5f}" if i < len(res[n]) else "-"
                for n in levels
            ]
            for rows in (production, band):
                fc = rows[0].get(round(h, 4)) if rows else None
                cols.append(f"{fc[0]:.4f} {fc[1]:.4f} {fc[2]:.5f}" if fc else "-")
            print(f"  {h:.1f} | " + " | ".join(cols), flush=True)
        if production:
            speed_table(p_air, levels, res, times, production, band)


if __name__ == "__main__":
    main()
