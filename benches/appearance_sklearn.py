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


def phantom_rows():
    """The widened phantoms: the same exported samples (every pyramid level the product
    trains on) and test pixels, per-class Dice of scikit-learn's argmax."""
    names = sorted(n for n in os.listdir(d) if n.startswith("synth-"))
    if not names:
        return
    print()
    print("| scikit-learn RF on the same samples: seed | kidney | tumour |")
    print("|---|---|---|")
    for n in names:
        p = os.path.join(d, n)
        meta = json.load(open(os.path.join(p, "meta.json")))
        f, k = meta["features"], meta["classes"]
        xtr = np.fromfile(os.path.join(p, "train_x.u8"), dtype=np.uint8).reshape(-1, f).astype(np.float32)
        ytr = np.fromfile(os.path.join(p, "train_y.u8"), dtype=np.uint8)
        xte = np.fromfile(os.path.join(p, "test_x.u8"), dtype=np.uint8).reshape(-1, f).astype(np.float32)
        yte = np.fromfile(os.path.join(p, "test_y.u8"), dtype=np.uint8)
        clf = RandomForestClassifier(n_estimators=20, n_jobs=2, random_state=0).fit(xtr, ytr)
        pred = clf.predict(xte)
        dice = [2.0 * ((pred == c) & (yte == c)).sum() / max(1, (pred == c).sum() + (yte == c).sum()) for c in range(k)]
        print(f"| {n[6:]} | {dice[1]:.3f} | {dice[2]:.3f} |", flush=True)


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
    return dict(name=name, kidney=kidney.ravel(), strokes=strokes.ravel(), ours=ours, bank=bank)


frames = [load(n) for n in meta["frames"]]


def dice(pred, truth):
    s = pred.sum() + truth.sum()
    return 1.0 if s == 0 else 2.0 * (pred & truth).sum() / s


def fit(xs, ys):
    clf = RandomForestClassifier(n_estimators=20, n_jobs=2, random_state=0)
    clf.fit(np.concatenate(xs), np.concatenate(ys))
    return clf


def evaluate(key, frames_set):
    same = []
    for f in frames_set:
        m = f["strokes"] > 0
        clf = fit([f[key][m]], [f["strokes"][m] - 1])
        pred = clf.predict(f[key]) == 1
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
        cross += [dice(clf.predict(frames_set[i][key]) == 1, frames_set[i]["kidney"]) for i in range(n) if i not in seeded]
    return np.mean(same), np.mean(cross)


tuning = [f for f in frames if f["name"].startswith("c16")]
test = [f for f in frames if not f["name"].startswith("c16")]
for key, label in [("ours", "scikit-learn RF, endofuse features"), ("bank", "scikit-learn RF, skimage multiscale_basic_features")]:
    ts, tc = evaluate(key, tuning)
    es, ec = evaluate(key, test)
    print(f"| {label} | {ts:.3f} | {tc:.3f} | {es:.3f} | {ec:.3f} |")
