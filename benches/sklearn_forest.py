#!/usr/bin/env python3
"""The scikit-learn half of `cargo bench --bench forest_vs_sklearn`: trains
RandomForestClassifier(n_estimators=20, n_jobs=THREADS, 2 unless given) on the exported features and reports training
time, inference throughput (predict_proba) and held-out accuracy as one JSON line, with the
accuracy of forests of further seeds (argv[3] in all) beside it.
Installs scikit-learn and numpy with pip when they are missing."""
import json, os, subprocess, sys, time

try:
    import numpy as np
    import sklearn
    from sklearn.ensemble import RandomForestClassifier
except ImportError:
    subprocess.check_call([sys.executable, "-m", "pip", "install", "-q", "scikit-learn", "numpy"], stdout=sys.stderr)
    import numpy as np
    import sklearn
    from sklearn.ensemble import RandomForestClassifier

d = sys.argv[1]
meta = json.load(open(os.path.join(d, "meta.json")))
f = meta["features"]
xtr = np.fromfile(os.path.join(d, "train_x.u8"), dtype=np.uint8).reshape(-1, f).astype(np.float32)
ytr = np.fromfile(os.path.join(d, "train_y.u8"), dtype=np.uint8)
xte = np.fromfile(os.path.join(d, "test_x.u8"), dtype=np.uint8).reshape(-1, f).astype(np.float32)
yte = np.fromfile(os.path.join(d, "test_y.u8"), dtype=np.uint8)

jobs = int(sys.argv[2]) if len(sys.argv) > 2 else 2
clf = RandomForestClassifier(n_estimators=20, n_jobs=jobs, random_state=0)
t = time.perf_counter()
clf.fit(xtr, ytr)
train_s = time.perf_counter() - t
best = float("inf")
for _ in range(3):
    t = time.perf_counter()
    p = clf.predict_proba(xte)
    best = min(best, time.perf_counter() - t)


def accuracy(forest, p):
    return float((forest.classes_[p.argmax(axis=1)] == yte).mean())


acc = accuracy(clf, p)
# A forest's accuracy moves with its seed: the bench compares the mean over several seeds.
seeds = int(sys.argv[3]) if len(sys.argv) > 3 else 1
seed_acc = [acc]
for seed in range(1, seeds):
    other = RandomForestClassifier(n_estimators=20, n_jobs=jobs, random_state=seed).fit(xtr, ytr)
    seed_acc.append(accuracy(other, other.predict_proba(xte)))
print(json.dumps({"train_s": train_s, "predict_px_per_s": len(yte) / best, "accuracy": acc,
                  "seed_accuracies": seed_acc, "version": "scikit-learn " + sklearn.__version__}))
