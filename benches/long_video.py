#!/usr/bin/env python3
"""Long videos (issue 17): a 10,000-frame 1080p stereo scene read from video files (or, with
`--source images`, from an image sequence), tracked as a user would, with its peak memory and time measured at two lengths to show both stay
bounded and linear.

    cargo build --release && python3 benches/long_video.py [--frames 10000] [--short 1000] [--source video|images]

Needs FFmpeg (ffmpeg, ffprobe) on PATH and GNU time (/usr/bin/time). The scene: `synth` writes
100 frames of 1920x1080 (tools, noise 0.02, no zoom); each view's video plays them forward
and back again (0..99, 98..1, ...) so the motion stays continuous for as long as asked, encoded
as H.264 (libx264, ultrafast, crf 18; one 198-frame cycle encoded, then repeated by stream
copy). With `--source images` each view is a folder of 10,000 PNG files named 000000.png ...,
hard links to the same 198-frame cycle (each file is opened and decoded like any other; the
links only spare the disk 60 GB). The scene.json points each camera at its video or sequence; the
ground truth is dropped (it covers 100 frames). `track --mode LS` runs the first SHORT frames
and then all FRAMES; the table gives wall time, ms per frame and peak RSS (GNU time's maximum
resident set size) of each. Not part of CI (the long run takes tens of minutes on 2 cores)."""
import argparse, json, os, re, shutil, subprocess, sys, time

root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
exe = os.path.join(root, "target", "release", "endofuse")
ap = argparse.ArgumentParser()
ap.add_argument("--frames", type=int, default=10000)
ap.add_argument("--short", type=int, default=1000)
ap.add_argument("--work", help="working folder (default target/long-video or target/long-images)")
ap.add_argument("--mode", default="LS")
ap.add_argument("--source", choices=("video", "images"), default="video")
a = ap.parse_args()
for tool in ("ffmpeg", "ffprobe"):
    if shutil.which(tool) is None:
        sys.exit(f"long_video: {tool} not found; install FFmpeg")
if not os.path.exists("/usr/bin/time"):
    sys.exit("long_video: GNU time (/usr/bin/time) not found; install the 'time' package")
if not os.path.exists(exe):
    sys.exit("long_video: build first: cargo build --release")

w = a.work or os.path.join(root, "target", "long-video" if a.source == "video" else "long-images")
src = os.path.join(w, "src")
scene_dir = os.path.join(w, "scene")
os.makedirs(w, exist_ok=True)
if not os.path.exists(os.path.join(src, "scene.json")):
    subprocess.run([exe, "synth", "--out", src, "--frames", "100", "--width", "1920", "--height", "1080",
                    "--noise", "0.02", "--no-zoom", "--seed", "17"], check=True)
scene = json.load(open(os.path.join(src, "scene.json")))
base = 100
cycle = list(range(base)) + list(range(base - 2, 0, -1))  # forward and back: 198 frames
os.makedirs(scene_dir, exist_ok=True)
def link_sequence(name):
    """A view as an image sequence: frame i is a hard link to the cycle's frame."""
    folder = os.path.join(scene_dir, name)
    stamp = folder + ".frames"
    want = f"{a.frames} frames"
    if not (os.path.exists(stamp) and open(stamp).read() == want):
        shutil.rmtree(folder, ignore_errors=True)
        os.makedirs(folder)
        for i in range(a.frames):
            t = cycle[i % len(cycle)]
            os.link(os.path.join(src, name, f"{t:06}.png"), os.path.join(folder, f"{i:06}.png"))
        open(stamp, "w").write(want)
    return f"{name}/{{frame:06}}.png"


for cam in scene["cameras"]:
    name = cam["name"]
    if a.source == "images":
        cam["frames"] = link_sequence(name)
        continue
    video = os.path.join(scene_dir, f"{name}.mp4")
    want = f"{a.frames} frames"
    stamp = video + ".frames"
    if not (os.path.exists(video) and os.path.exists(stamp) and open(stamp).read() == want):
        t0 = time.time()
        # One cycle encoded, then repeated without re-encoding (stream copy) to the length.
        lst = os.path.join(w, f"{name}.txt")
        with open(lst, "w") as f:
            for t in cycle:
                f.write(f"file '{os.path.join(src, name, f'{t:06}.png')}'\nduration 0.04\n")
        one = os.path.join(w, f"{name}-cycle.mp4")
        subprocess.run(["ffmpeg", "-loglevel", "error", "-y", "-f", "concat", "-safe", "0", "-i", lst,
                        "-fps_mode", "passthrough", "-c:v", "libx264", "-preset", "ultrafast", "-crf", "18",
                        "-g", str(len(cycle)), "-pix_fmt", "yuv420p", one], check=True)
        loops = (a.frames + len(cycle) - 1) // len(cycle)
        subprocess.run(["ffmpeg", "-loglevel", "error", "-y", "-stream_loop", str(loops - 1), "-i", one,
                        "-c", "copy", "-frames:v", str(a.frames), video], check=True)
        open(stamp, "w").write(want)
        print(f"encoded {name}: {a.frames} frames in {time.time() - t0:.0f} s", flush=True)
    cam["frames"] = f"{name}.mp4"
scene["frame_count"] = a.frames
scene.pop("ground_truth", None)
scene["fps"] = 25
# Meshes, catalogs and seeds as synth wrote them; the frames come from the videos.
for entry in os.listdir(src):
    path = os.path.join(src, entry)
    if os.path.isdir(path) and entry not in ("gt",) and entry not in [c["name"] for c in scene["cameras"]]:
        shutil.copytree(path, os.path.join(scene_dir, entry), dirs_exist_ok=True)
json.dump(scene, open(os.path.join(scene_dir, "scene.json"), "w"), indent=1)

rows = []
for n in sorted({a.short, a.frames}):
    out = os.path.join(w, f"out-{n}")
    shutil.rmtree(out, ignore_errors=True)
    t0 = time.time()
    run = subprocess.run(["/usr/bin/time", "-v", exe, "track", scene_dir, "--out", out, "--mode", a.mode,
                          "--frames", f"0..{n - 1}"], capture_output=True, text=True)
    wall = time.time() - t0
    if run.returncode != 0:
        sys.exit(f"track of {n} frames failed:\n{run.stderr[-3000:]}")
    rss_kb = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", run.stderr).group(1))
    metrics = json.load(open(os.path.join(out, "metrics.json")))
    median = metrics["timing"]["ms_per_frame"]["median"]
    lost = metrics.get("lost_frames", 0)
    rows.append((n, wall, 1000 * wall / n, median, rss_kb / 1024, lost))
    print(f"tracked {n} frames in {wall:.0f} s", flush=True)
    shutil.rmtree(out, ignore_errors=True)

print()
kind = "H.264" if a.source == "video" else "PNG sequence"
print(f"| frames (1920x1080 stereo, {kind}, track --mode {a.mode}) | wall s | ms per frame, all work | fit ms per frame (median) | peak RSS MiB | lost frames |")
print("|---|---|---|---|---|---|")
for n, wall, per, median, rss, lost in rows:
    print(f"| {n} | {wall:.0f} | {per:.1f} | {median:.1f} | {rss:.0f} | {lost} |")
