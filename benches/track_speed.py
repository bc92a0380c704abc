#!/usr/bin/env python3
"""Benchmark: the fit's time per frame of two or more builds, side by side (issue 14).

    python3 benches/track_speed.py BUILD_A,BUILD_B SCENE_DIR[,SCENE_DIR…] [--mode LS] [--pairs 4]

Runs `BUILD track SCENE --mode MODE` for each build in turn, alternating which goes first, so
that both meet the same state of the machine, and prints per scene each build's median of the
tracker's own "ms per frame (median)", its fastest run, and the median of the per-pair ratios
against the first build (the steadiest figure on a shared machine, whose speed drifts by
±10 % within an hour). `RAYON_NUM_THREADS=1` in the environment measures one core.

Scenes are any scene folders, e.g. those `benches/fit_heldout.py --keep DIR` leaves in DIR
(`DIR/scene-1501`). Not part of CI.
"""

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile

MEDIAN = re.compile(r"([0-9.]+) ms per frame \(median\)")


def frame_ms(build, scene, mode, out):
    r = subprocess.run(
        [build, "track", scene, "--out", out, "--mode", mode], capture_output=True, text=True
    )
    m = MEDIAN.search(r.stderr)
    if r.returncode != 0 or not m:
        sys.exit(f"{build} track {scene} failed:\n{r.stderr[-2000:]}")
    return float(m.group(1))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("builds", help="comma-separated endofuse binaries; the first is the reference")
    ap.add_argument("scenes", help="comma-separated scene folders")
    ap.add_argument("--mode", default="LS")
    ap.add_argument("--pairs", type=int, default=4)
    a = ap.parse_args()
    builds = a.builds.split(",")
    for b in builds:
        if not os.access(b, os.X_OK):
            sys.exit(f"not an executable: {b}")
    work = tempfile.mkdtemp(prefix="track-speed-")
    for scene in a.scenes.split(","):
        times = {b: [] for b in builds}
        for k in range(a.pairs):
            for b in builds if k % 2 == 0 else builds[::-1]:
                out = os.path.join(work, f"{os.path.basename(scene)}-{builds.index(b)}")
                times[b].append(frame_ms(b, scene, a.mode, out))
        ref = times[builds[0]]
        cells = []
        for b, t in times.items():
            ratio = statistics.median(x / y for x, y in zip(t, ref))
            cells.append(
                f"{os.path.basename(b)}: median {statistics.median(t):.1f} ms, "
                f"fastest {min(t):.1f}, ratio {ratio:.3f}"
            )
        print(f"{os.path.basename(scene)} {a.mode}: " + "; ".join(cells), flush=True)


if __name__ == "__main__":
    main()
