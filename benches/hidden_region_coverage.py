#!/usr/bin/env python3
"""Is the hidden tumour's 95 % region calibrated (issue 16)? Widened phantoms with truth are
tracked as a user would, and for every frame the true centroid is tested against the sphere
`trajectory.json` gives (`hidden_region`): coverage (share of frames inside, 90-98 % wanted)
and the median radius per mode, on a tuning set and a held-out test set.

    cargo build --release && python3 benches/hidden_region_coverage.py [--set tuning|test|both]
        [--modes LSC,LS,L,R] [--keep DIR] [--calibrate]

`--calibrate` (tuning set only) also searches the two constants the images cannot know,
`hidden_region.covariance_scale` s and `hidden_region.model_error_mm` e: the covariance the
tracker wrote with the constants it ran with is taken apart into its data part and rebuilt for
each (s, e); the pair with the smallest median radius whose coverage is at least 95 % on the
tuning frames is printed, to be made the default. The seeds below were fixed before any
constant was chosen; the test set is never used to choose. Not part of CI: about half a
minute per scene and mode on 2 cores.
"""

import argparse
import json
import math
import os
import random
import statistics
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import fit_heldout as heldout  # noqa: E402  (the widened phantoms and how to run the CLI)

BIN, run = heldout.BIN, heldout.run

# (seed, width, height, noise, views, kits case or None, zoom)
# The first calibration (session 2026-12-02) chose on 501-506 and reported 601-608; the second
# (the rim residual's share k and the lost-frame growth) looked at 601-608's misses, so they
# joined the tuning set, and 701-710 were fixed as the test set before k and g were chosen.
# The third (session 2026-12-02, later: which frame quantities predict the error) looked at
# 701-710 frame by frame, so they joined the tuning set too, and 801-812 were fixed as the test
# set before anything was chosen: no KiTS shape but case_00023 (the one endophytic patient
# tumour, whose shape 606 tunes on: the others have no hidden tumour to score).
TUNING = [
    (501, 480, 270, 0.02, 2, None, True),
    (502, 480, 270, 0.05, 2, None, True),
    (503, 480, 270, 0.03, 2, None, False),
    (504, 480, 270, 0.03, 2, "case_00009", True),
    (505, 640, 360, 0.05, 2, None, True),
    (506, 480, 270, 0.02, 4, None, True),
    (601, 480, 270, 0.02, 2, None, True),
    (602, 480, 270, 0.05, 2, None, True),
    (603, 640, 360, 0.03, 2, None, True),
    (604, 480, 270, 0.05, 2, None, False),
    (605, 480, 270, 0.03, 2, "case_00015", True),
    (606, 480, 270, 0.05, 2, "case_00023", True),
    (607, 480, 270, 0.02, 4, None, True),
    (608, 960, 540, 0.03, 2, None, True),
    (701, 480, 270, 0.03, 2, None, True),
    (702, 480, 270, 0.05, 2, "case_00041", True),
    (703, 640, 360, 0.02, 2, None, True),
    (704, 480, 270, 0.05, 2, None, False),
    (705, 480, 270, 0.03, 2, "case_00057", True),
    (706, 960, 540, 0.05, 2, None, True),
    (707, 480, 270, 0.02, 4, "case_00082", True),
    (708, 480, 270, 0.04, 2, "case_00109", True),
    (709, 640, 360, 0.05, 2, None, True),
    (710, 480, 270, 0.03, 2, "case_00130", False),
]
TEST = [
    (801, 480, 270, 0.03, 2, None, True),
    (802, 480, 270, 0.05, 2, None, True),
    (803, 640, 360, 0.02, 2, None, True),
    (804, 480, 270, 0.04, 2, None, False),
    (805, 960, 540, 0.03, 2, None, True),
    (806, 480, 270, 0.05, 4, None, True),
    (807, 640, 360, 0.05, 2, None, True),
    (808, 480, 270, 0.02, 2, "case_00023", True),
    (809, 960, 540, 0.05, 2, None, True),
    (810, 480, 270, 0.03, 2, None, True),
    (811, 640, 360, 0.04, 4, None, True),
    (812, 480, 270, 0.02, 2, None, False),
]
FRAMES = 24


def make_scene(spec, work):
    return heldout.make_scene(spec, work, frames=FRAMES)


# The data part alone: what the calibration rebuilds the region from.
RAW = {"hidden_region": {"covariance_scale": 1.0, "model_error_mm": 0.0,
                         "model_error_per_rim_residual": 0.0, "lost_growth_mm_per_frame": 0.0,
                         "zoom_depth_sd_corrected": 0.0, "zoom_depth_sd_uncorrected": 0.0}}


def track(scene, mode, work, tag, raw=False):
    out = os.path.join(work, f"track-{tag}-{mode}" + ("-raw" if raw else ""))
    if not os.path.exists(os.path.join(out, "metrics.json")):
        args = [BIN, "track", scene, "--out", out, "--mode", mode]
        if raw:
            config = os.path.join(work, "raw-config.json")
            with open(config, "w") as f:
                json.dump(RAW, f)
            args += ["--config", config]
        run(args)
    with open(os.path.join(out, "metrics.json")) as f:
        metrics = json.load(f)
    with open(os.path.join(out, "trajectory.json")) as f:
        fitted = json.load(f)
    with open(os.path.join(scene, "gt", "trajectory.json")) as f:
        truth = {fr["frame"]: fr for fr in json.load(f)["frames"]}
    with open(os.path.join(scene, "scene.json")) as f:
        changes = json.load(f).get("zoom_changes", [])
    first_zoom = min((c[0] for c in changes), default=None)
    zoomed = False
    rows = []
    lost_run = 0
    for fr in fitted["frames"]:
        lost_run = lost_run + 1 if fr.get("lost", False) else 0
        # As the tracker keeps it: from the first zoomed frame on (a marked change, or a
        # frame where depth followed a zoom).
        zoomed = zoomed or (first_zoom is not None and fr["frame"] >= first_zoom) \
            or "depth_explains_zoom" in fr.get("warnings", [])
        gt = truth.get(fr["frame"])
        for name, region in fr.get("hidden_region", {}).items():
            if gt is None or name not in gt.get("centroids", {}):
                continue
            err = [a - b for a, b in zip(gt["centroids"][name], fr["centroids"][name])]
            rows.append({"err": err, "cov": region["centroid_cov_mm2"],
                         "radius": region["radius95_mm"], "lost": lost_run,
                         "rim": region.get("rim_residual_mm", 0.0),
                         "c": fr["centroids"][name], "zoomed": zoomed})
    config = metrics.get("config", {}).get("fit", {}).get("hidden_region", {})
    return rows, metrics, config


# --- the radius of a Gaussian, as the tracker computes it (fixed normal samples) -------------

_SAMPLES = None


def samples():
    global _SAMPLES
    if _SAMPLES is None:
        rng = random.Random(95)
        _SAMPLES = [(rng.gauss(0, 1), rng.gauss(0, 1), rng.gauss(0, 1)) for _ in range(4096)]
    return _SAMPLES


def eigenvalues_sym3(m):
    """Eigenvalues of a symmetric 3×3 matrix (closed form)."""
    a, b, c = m[0][0], m[1][1], m[2][2]
    d, e, f = m[0][1], m[1][2], m[0][2]
    p1 = d * d + e * e + f * f
    if p1 < 1e-30:
        return [a, b, c]
    q = (a + b + c) / 3
    p2 = (a - q) ** 2 + (b - q) ** 2 + (c - q) ** 2 + 2 * p1
    p = math.sqrt(p2 / 6)
    B = [[(m[i][j] - (q if i == j else 0)) / p for j in range(3)] for i in range(3)]
    det = (B[0][0] * (B[1][1] * B[2][2] - B[1][2] * B[2][1])
           - B[0][1] * (B[1][0] * B[2][2] - B[1][2] * B[2][0])
           + B[0][2] * (B[1][0] * B[2][1] - B[1][1] * B[2][0]))
    r = max(-1.0, min(1.0, det / 2))
    phi = math.acos(r) / 3
    l1 = q + 2 * p * math.cos(phi)
    l3 = q + 2 * p * math.cos(phi + 2 * math.pi / 3)
    return [l1, 3 * q - l1 - l3, l3]


def radius95(cov):
    try:
        import numpy as np
    except ImportError:
        np = None
    if np is not None:
        global _Z2
        if "_Z2" not in globals():
            _Z2 = np.array(samples()) ** 2
        l = np.maximum(np.linalg.eigvalsh(np.array(cov)), 0.0)
        q = np.sort(_Z2 @ l)
        return float(np.sqrt(q[math.ceil(0.95 * len(q)) - 1]))
    l = [max(v, 0.0) for v in eigenvalues_sym3(cov)]
    q = sorted(l[0] * x * x + l[1] * y * y + l[2] * z * z for x, y, z in samples())
    return math.sqrt(q[math.ceil(0.95 * len(q)) - 1])


def rebuilt(row, s, e, d, k=0.0, g=0.0):
    """A raw row's covariance (data part alone) with the constants (s, e, d, k, g), as the
    tracker builds it: s · data + (e² + (k · rim)²) I + d² c cᵀ after a zoom, + (g · n)² I
    n frames into a loss. A lost frame's row holds the last good frame's data part and
    centroid; its rim residual is that frame's too."""
    c = row["c"]
    dz = d if row["zoomed"] else 0.0
    diag = e * e + (k * row["rim"]) ** 2 + (g * row["lost"]) ** 2
    return [[s * row["cov"][i][j] + (diag if i == j else 0) + dz * dz * c[i] * c[j]
             for j in range(3)] for i in range(3)]


def inside(row, radius):
    return math.sqrt(sum(v * v for v in row["err"])) <= radius


def coverage(rows, *constants):
    radii = [radius95(rebuilt(r, *constants)) for r in rows]
    cover = sum(inside(r, rad) for r, rad in zip(rows, radii)) / len(rows)
    return cover, statistics.median(radii)


def calibrate(rows, ds):
    """The (s, e, d, k) with the smallest median radius whose coverage of the frames tracked
    is at least 95 %, then the lost-frame growth g: the smallest on its grid whose coverage of
    the lost frames is at least 95 % (or the largest)."""
    good = [r for r in rows if not r["lost"]]
    lost = [r for r in rows if r["lost"]]
    best = None
    for s in [0.5, 1, 2, 4, 8, 16]:
        for e in [0.0, 0.5, 0.75, 1.0, 1.25, 1.5, 2.0]:
            for d in ds:
                for k in [0.0, 0.5, 1.0, 1.5, 2.0, 3.0]:
                    cover, med = coverage(good, s, e, d, k)
                    if cover >= 0.95 and (best is None or med < best[4]):
                        best = (s, e, d, k, med, cover)
    if best is None:
        return None
    g_grid = [0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0]
    g = g_grid[-1]
    for cand in g_grid:
        if lost and coverage(lost, *best[:4], cand)[0] >= 0.95:
            g = cand
            break
    return best + (g, coverage(rows, *best[:4], g), len(lost))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--set", choices=["tuning", "test", "both"], default="both")
    ap.add_argument("--modes", default="LSC,LS")
    ap.add_argument("--keep", help="keep scenes and results in this folder")
    ap.add_argument("--calibrate", action="store_true")
    args = ap.parse_args()
    if not os.path.exists(BIN):
        sys.exit(f"{BIN} not found: run `cargo build --release` first")
    work = args.keep or tempfile.mkdtemp(prefix="hidden-region-")
    os.makedirs(work, exist_ok=True)
    sets = {"tuning": TUNING, "test": TEST}
    chosen = ["tuning", "test"] if args.set == "both" else [args.set]
    modes = args.modes.split(",")
    print("| set | mode | frames | coverage (95 % sphere) | median radius (mm) | mean centroid error (mm) | worst (mm) |")
    print("|---|---|---|---|---|---|---|")
    for name in chosen:
        for mode in modes:
            rows, config = [], {}
            # Calibrating needs the data part alone (the "raw" runs); the tracked figures
            # with the chosen constants come from a plain run after they are made defaults.
            for spec in sets[name] if not (args.calibrate and name == "tuning") else []:
                scene = make_scene(spec, work)
                r, _, config = track(scene, mode, work, spec[0])
                rows.extend(r)
            if not rows and not args.calibrate:
                print(f"| {name} | {mode} | 0 | – | – | – | – |")
                continue
            if rows:
                cover = sum(inside(r, r["radius"]) for r in rows) / len(rows)
                errs = [math.sqrt(sum(v * v for v in r["err"])) for r in rows]
                print(f"| {name} | {mode} | {len(rows)} | {100 * cover:.1f} % | "
                      f"{statistics.median(r['radius'] for r in rows):.2f} | "
                      f"{statistics.mean(errs):.2f} | {max(errs):.2f} |", flush=True)
            if args.calibrate and name == "tuning":
                raw = []
                for spec in sets[name]:
                    r, _, _ = track(make_scene(spec, work), mode, work, spec[0], raw=True)
                    raw.extend(r)
                ds = [0.0, 0.01, 0.015, 0.02, 0.025, 0.03, 0.04] if mode == "LSC" \
                    else [0.0, 0.02, 0.04, 0.06, 0.08, 0.1, 0.12, 0.15]
                best = calibrate(raw, ds)
                if best:
                    s_, e_, d_, k_, med, cover, g_, (all_cover, all_med), n_lost = best
                    print(f"  calibrated on {mode}: covariance_scale {s_}, model_error_mm {e_}, "
                          f"zoom depth sd {d_}, model_error_per_rim_residual {k_}: coverage "
                          f"{100 * cover:.1f} %, median radius {med:.2f} mm (tracked frames); "
                          f"lost_growth_mm_per_frame {g_} over {n_lost} lost frames; all "
                          f"frames {100 * all_cover:.1f} %, median {all_med:.2f} mm", flush=True)
                else:
                    print(f"  calibrated on {mode}: nothing on the grid reaches 95 %")
    if not args.keep:
        print(f"(scenes and results in {work})")


if __name__ == "__main__":
    main()
