#!/usr/bin/env python3
"""The scikit-learn half of `APPEARANCE_SKLEARN=1 cargo bench --bench appearance_heldout`:
the same frames, strokes and protocols (same frame: Dice on unpainted pixels; cross frame:
strokes on three frames of a set in turn, Dice on the others), with
RandomForestClassifier(n_estimators=20) on (a) endofuse's own features and (b) skimage's
multiscale_basic_features (intensity, edges, texture at sigma 0.5-16 on each RGB channel: the
ilastik-like baseline). Prints rows of the same Markdown table. Installs scikit-learn and
scikit-image with pip when missing."""
import json, os, subprocess, sys

try:
    import numpy as np
    from PIL import Image
    from sklearn.ensemble import RandomForestClassifier
    from skimage.feature import multiscale_basic_features
except ImportError:
    subprocess.check_call([sys.executable, "-m", "pip", "install", "-q", "scikit-learn", "scikit-image", "numpy", "pillow"], stdout=sys.stderr)
    import numpy as np
    from PIL import Image
    from sklearn.ensemble import RandomForestClassifier
    from skimage.feature import multiscale_basic_features

d = sys.argv[1]


def smoothed(prob, h, w, sigma):
    """endofuse's smoothing of probability maps (prob: pixels × classes of an h×w frame):
    three clamped box passes of radius r per axis (appearance/smooth.rs)."""
    r = int(round((np.sqrt(4 * sigma * sigma + 1) - 1) / 2))
    if r == 0:
        return prob
    p = prob.reshape(h, w, -1).astype(np.float64)
    for axis in (1, 0):
        for _ in range(3):
            n = p.shape[axis]
            pad = [(0, 0)] * 3
            pad[axis] = (r + 1, r)
            c = np.cumsum(np.pad(p, pad, mode="edge"), axis=axis)
            hi = np.take(c, np.arange(2 * r + 1, 2 * r + 1 + n), axis=axis)
            lo = np.take(c, np.arange(0, n), axis=axis)
            p = (hi - lo) / (2 * r + 1)
    return p.reshape(h * w, -1)


def phantom_rows():
    """The widened phantoms: the same exported samples (every pyramid level the product
    trains on) and test pixels, per-class Dice of scikit-learn's argmax."""
    names = sorted(n for n in os.listdir(d) if n.startswith("synth-"))
    if not names:
        return
    print()
    print("| scikit-learn RF on the same samples: seed | kidney | tumour | kidney, smoothed as endofuse | tumour, smoothed |")
    print("|---|---|---|---|---|")
    for n in names:
        p = os.path.join(d, n)
        meta = json.load(open(os.path.join(p, "meta.json")))
        f, k = meta["features"], meta["classes"]
        xtr = np.fromfile(os.path.join(p, "train_x.u8"), dtype=np.uint8).reshape(-1, f).astype(np.float32)
        ytr = np.fromfile(os.path.join(p, "train_y.u8"), dtype=np.uint8)
        xte = np.fromfile(os.path.join(p, "test_x.u8"), dtype=np.uint8).reshape(-1, f).astype(np.float32)
        yte = np.fromfile(os.path.join(p, "test_y.u8"), dtype=np.uint8)
        clf = RandomForestClassifier(n_estimators=20, n_jobs=2, random_state=0).fit(xtr, ytr)
        prob = clf.predict_proba(xte)
        pred = prob.argmax(1)
        h, w = meta["height"], meta["width"]
        frames_n = len(yte) // (h * w)
        spred = np.concatenate([smoothed(prob[i * h * w:(i + 1) * h * w], h, w, meta["smooth_px"]).argmax(1) for i in range(frames_n)])

        def dice(pr):
            return [2.0 * ((pr == c) & (yte == c)).sum() / max(1, (pr == c).sum() + (yte == c).sum()) for c in range(k)]

        a, b = dice(pred), dice(spred)
        print(f"| {n[6:]} | {a[1]:.3f} | {a[2]:.3f} | {b[1]:.3f} | {b[2]:.3f} |", flush=True)


phantom_rows()
if not os.path.exists(os.path.join(d, "frames.json")):
    sys.exit(0)
meta = json.load(open(os.path.join(d, "frames.json")))
F = meta["features"]


def load(name):
    img = np.array(Image.open(os.path.join(d, f"{name}_image.png")).convert("RGB"))
    kidney = np.array(Image.open(os.path.join(d, f"{name}_kidney.png"))) > 0
    strokes = np.array(Image.open(os.path.join(d, f"{name}_strokes.png")))
    h, w = kidney.shape
    ours = np.fromfile(os.path.join(d, f"{name}_ours.u8"), dtype=np.uint8).reshape(h * w, F).astype(np.float32)
    bank = multiscale_basic_features(img, channel_axis=-1).reshape(h * w, -1).astype(np.float32)
    return dict(name=name, kidney=kidney.ravel(), strokes=strokes.ravel(), ours=ours, bank=bank, h=h, w=w)


frames = [load(n) for n in meta["frames"]]


def dice(pred, truth):
    s = pred.sum() + truth.sum()
    return 1.0 if s == 0 else 2.0 * (pred & truth).sum() / s


def fit(xs, ys):
    clf = RandomForestClassifier(n_estimators=20, n_jobs=2, random_state=0)
    clf.fit(np.concatenate(xs), np.concatenate(ys))
    return clf


def kidney(clf, f, key, sigma):
    """Pixels scikit-learn calls kidney, its probabilities smoothed as endofuse's (σ 0: not)."""
    return smoothed(clf.predict_proba(f[key]), f["h"], f["w"], sigma).argmax(1) == 1


def evaluate(key, frames_set, sigma):
    same = []
    for f in frames_set:
        m = f["strokes"] > 0
        clf = fit([f[key][m]], [f["strokes"][m] - 1])
        pred = kidney(clf, f, key, sigma)
        u = ~m
        same.append(dice(pred[u], f["kidney"][u]))
    n = len(frames_set)
    cross = []
    for r in range(n):
        seeded = [(r + j) % n for j in range(min(3, n - 1))]
        xs, ys = [], []
        for i in seeded:
            m = frames_set[i]["strokes"] > 0
            xs.append(frames_set[i][key][m])
            ys.append(frames_set[i]["strokes"][m] - 1)
        clf = fit(xs, ys)
        cross += [dice(kidney(clf, frames_set[i], key, sigma), frames_set[i]["kidney"]) for i in range(n) if i not in seeded]
    return np.mean(same), np.mean(cross)


tuning = [f for f in frames if f["name"].startswith("c16")]
test = [f for f in frames if not f["name"].startswith("c16")]
for key, label in [("ours", "scikit-learn RF, endofuse features"), ("bank", "scikit-learn RF, skimage multiscale_basic_features")]:
    for sigma, how in [(0.0, ""), (meta.get("smooth_px", 0.0), ", smoothed as endofuse")]:
        ts, tc = evaluate(key, tuning, sigma)
        es, ec = evaluate(key, test, sigma)
        print(f"| {label}{how} | {ts:.3f} | {tc:.3f} | {es:.3f} | {ec:.3f} |", flush=True)
