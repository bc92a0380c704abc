"""Segments the images benches/chan_vese_vs_skimage.rs wrote with scikit-image's chan_vese
(its defaults), writing one mask per image for the bench to compare with ours.

Usage (the bench runs it): python3 benches/chan_vese_skimage.py DIR
DIR holds NAME.f32 (row-major little-endian float32) and NAME.json ({"width", "height"});
writes NAME.skimage.u8 (1 inside, 0 outside) and NAME.skimage.json (iterations, seconds).
"""
import json
import pathlib
import sys
import time

import numpy as np
from skimage.segmentation import chan_vese

folder = pathlib.Path(sys.argv[1])
for meta_path in sorted(folder.glob("*.json")):
    if meta_path.name.endswith(".skimage.json"):
        continue
    meta = json.loads(meta_path.read_text())
    name = meta_path.stem
    img = np.fromfile(folder / f"{name}.f32", dtype="<f4").reshape(meta["height"], meta["width"])
    started = time.perf_counter()
    seg, _phi, energies = chan_vese(img.astype(np.float64), extended_output=True)
    seconds = time.perf_counter() - started
    seg.astype(np.uint8).tofile(folder / f"{name}.skimage.u8")
    (folder / f"{name}.skimage.json").write_text(
        json.dumps({"iterations": len(energies), "seconds": seconds})
    )
    print(f"{name}: {len(energies)} iterations, {seconds:.1f} s", file=sys.stderr)
