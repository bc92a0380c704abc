#!/usr/bin/env python3
"""The fit on scenes it was not tuned on (issue 14): a tuning set and a held-out test set of
widened phantoms, tracked in LS and LSC as a user would, and the table of Dice, hidden-tumour
centroid error, camera errors and ms per frame for each.

    cargo build --release && python3 benches/fit_heldout.py [--set tuning|test|both|hard] [--keep DIR]

Every scene is `endofuse synth --vary-rig` (toe-in 1-2 deg, the right principal point up to
2 px off, k2 and p1/p2, a 20 % zoom over 10-15 frames that half the scenes undo, the principal
point drifting up to 4 px, depth 145-165 mm, a start 8 mm and 10 deg off), with the look
drawn too (`--vary-look`), noise up to 0.10, tools, smoke, and for some a patient's kidney
and tumours (`import-ct` of a KiTS19 label volume from ../shared/data/kits19-shape-set, or
../shared/data/kits19 from the eleventh test set on: ~5k-vertex meshes). The seeds below were
fixed before any setting was tuned on the tuning set; the test set is never used to choose.
Not part of CI: about 1 minute per scene on 2 cores.

The last column takes the LSC hidden-tumour error apart (issue 14: what limits it, measured): the
visible kidney's own centroid error along camera 0's axis (the pose's depth) and across it, and
the hidden structure's error once the kidney's is taken out (misplaced inside the kidney).
"""

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# ENDOFUSE_BIN runs another build (an earlier main, for a side-by-side table).
BIN = os.environ.get("ENDOFUSE_BIN") or os.path.join(ROOT, "target", "release", "endofuse")
KITS = os.path.join(ROOT, "..", "shared", "data", "kits19-shape-set")
# The three developer fixtures' patients, kept apart from the shape set.
KITS_FIXTURES = os.path.join(ROOT, "..", "shared", "data", "kits19")


def kits_volume(case):
    """A KiTS19 label volume from the shape set, else from the fixtures' folder."""
    shape_set = os.path.join(KITS, f"{case}.segmentation.nii.gz")
    if os.path.exists(shape_set):
        return shape_set
    return os.path.join(KITS_FIXTURES, case, "segmentation.nii.gz")

# (seed, width, height, noise, views, kits case or None, zoom)
TUNING = [
    (301, 960, 540, 0.03, 2, None, True),
    (302, 960, 540, 0.05, 2, None, True),
    (303, 480, 270, 0.10, 2, None, False),
    (304, 480, 270, 0.03, 2, "case_00009", True),
    (305, 480, 270, 0.05, 4, None, False),
    (306, 960, 540, 0.02, 2, "case_00013", True),
    # The first test set: after the session of 2026-12-03 (the firmer shape prior) had been
    # reported on it, it joined the tuning set, and 901-912 were fixed before anything else.
    (401, 960, 540, 0.03, 2, None, True),
    (402, 960, 540, 0.05, 2, None, True),
    (403, 960, 540, 0.02, 2, None, False),
    (404, 480, 270, 0.10, 2, None, True),
    (405, 480, 270, 0.10, 2, None, False),
    (406, 480, 270, 0.05, 2, "case_00015", True),
    (407, 480, 270, 0.03, 2, "case_00023", False),
    (408, 480, 270, 0.05, 4, None, True),
    (409, 960, 540, 0.03, 2, "case_00041", True),
    (410, 480, 270, 0.03, 2, "case_00045", True),
    (411, 960, 540, 0.10, 2, None, True),
    (412, 480, 270, 0.02, 4, "case_00050", False),
    # The second test set: reported twice (2026-12-03 and -04), and scene 901's lost zoom-out
    # was studied on 2026-12-04 before the zoom's coarser level was chosen, so it joined the
    # tuning set; 1301-1312 were fixed before that choice was measured on the tuning set.
    (901, 960, 540, 0.03, 2, None, True),
    (902, 960, 540, 0.10, 2, None, True),
    (903, 960, 540, 0.05, 2, None, False),
    (904, 480, 270, 0.10, 2, None, True),
    (905, 480, 270, 0.08, 2, None, False),
    (906, 480, 270, 0.05, 2, "case_00057", True),
    (907, 480, 270, 0.05, 2, "case_00023", True),
    (908, 480, 270, 0.03, 4, None, True),
    (909, 960, 540, 0.02, 2, "case_00083", False),
    (910, 480, 270, 0.10, 2, None, True),
    (911, 960, 540, 0.05, 2, None, True),
    (912, 480, 270, 0.03, 4, "case_00130", True),
    # The third test set: reported at four stops of 2026-12-04, and the fourth run validated the
    # zoom's looser pose hold, so it joined the tuning set; 1401-1412 were fixed on 2026-12-04
    # (fourth session) before anything of that session was measured.
    (1301, 960, 540, 0.03, 2, None, True),
    (1302, 960, 540, 0.08, 2, None, True),
    (1303, 960, 540, 0.05, 2, None, False),
    (1304, 480, 270, 0.10, 2, None, True),
    (1305, 480, 270, 0.05, 2, None, False),
    (1306, 480, 270, 0.05, 2, "case_00007", True),
    (1307, 480, 270, 0.03, 2, "case_00051", True),
    (1308, 480, 270, 0.05, 4, None, True),
    (1309, 960, 540, 0.02, 2, "case_00065", True),
    (1310, 480, 270, 0.10, 2, None, True),
    (1311, 960, 540, 0.10, 2, None, True),
    (1312, 480, 270, 0.03, 4, "case_00090", False),
    # The fourth test set: reported twice on 2026-12-04 (before and after the stereo weight
    # 64), so it joined the tuning set; 1501-1512 were fixed on 2026-12-04 (fifth session)
    # before anything of that session was measured.
    (1401, 960, 540, 0.05, 2, None, True),
    (1402, 960, 540, 0.10, 2, None, False),
    (1403, 960, 540, 0.03, 2, "case_00117", True),
    (1404, 480, 270, 0.08, 2, None, True),
    (1405, 480, 270, 0.10, 2, None, False),
    (1406, 480, 270, 0.03, 2, "case_00082", True),
    (1407, 480, 270, 0.05, 2, "case_00144", False),
    (1408, 480, 270, 0.05, 4, None, True),
    (1409, 960, 540, 0.02, 2, None, True),
    (1410, 480, 270, 0.10, 2, "case_00174", True),
    (1411, 960, 540, 0.08, 2, None, True),
    (1412, 480, 270, 0.03, 4, None, True),
    # The fifth test set: reported on 2026-12-04 and rerun (same fit) on 2026-12-05, so it
    # joined the tuning set; 1701-1712 were fixed on 2026-12-05 (seventh session) before
    # anything of that session was measured, with four KiTS patients not used before.
    (1501, 960, 540, 0.03, 2, None, True),
    (1502, 960, 540, 0.08, 2, None, True),
    (1503, 960, 540, 0.05, 2, "case_00125", False),
    (1504, 480, 270, 0.10, 2, None, True),
    (1505, 480, 270, 0.05, 2, None, False),
    (1506, 480, 270, 0.03, 2, "case_00145", True),
    (1507, 480, 270, 0.08, 2, "case_00166", True),
    (1508, 480, 270, 0.05, 4, None, True),
    (1509, 960, 540, 0.02, 2, None, True),
    (1510, 480, 270, 0.10, 2, None, True),
    (1511, 960, 540, 0.10, 2, None, False),
    (1512, 480, 270, 0.03, 4, "case_00201", True),

    # The sixth test set: run once on 2026-12-05 (seventh session) with the phantom's tool
    # wedges fixed, so it joined the tuning set; 1901-1912 were fixed the same day before the
    # first frame's pose damping was measured.
    (1701, 960, 540, 0.05, 2, None, True),
    (1702, 960, 540, 0.03, 2, "case_00127", True),
    (1703, 960, 540, 0.08, 2, None, False),
    (1704, 480, 270, 0.10, 2, None, True),
    (1705, 480, 270, 0.03, 2, "case_00137", True),
    (1706, 480, 270, 0.05, 2, None, True),
    (1707, 480, 270, 0.08, 2, "case_00149", False),
    (1708, 480, 270, 0.05, 4, None, True),
    (1709, 960, 540, 0.02, 2, None, True),
    (1710, 480, 270, 0.10, 2, "case_00204", True),
    (1711, 960, 540, 0.10, 2, None, True),
    (1712, 480, 270, 0.03, 4, None, False),
    # The seventh test set: run once on 2026-12-05 (eighth session) after the first frame's
    # pose damping was chosen (0.1 -> 0.03), so it joined the tuning set; 2101-2112 were fixed
    # the same day before anything else was chosen.
    (1901, 960, 540, 0.03, 2, None, True),
    (1902, 960, 540, 0.05, 2, "case_00134", True),
    (1903, 960, 540, 0.10, 2, None, False),
    (1904, 480, 270, 0.08, 2, None, True),
    (1905, 480, 270, 0.03, 2, "case_00138", True),
    (1906, 480, 270, 0.05, 2, None, True),
    (1907, 480, 270, 0.10, 2, "case_00153", False),
    (1908, 480, 270, 0.05, 4, None, True),
    (1909, 960, 540, 0.02, 2, None, True),
    (1910, 480, 270, 0.08, 2, None, True),
    (1911, 960, 540, 0.08, 2, None, True),
    (1912, 480, 270, 0.03, 4, "case_00050", True),
    # The eighth test set: run once on 2026-12-05 (eighth session) with the final build of
    # that session (nothing of the fit chosen after it was fixed), so it joined the tuning set;
    # 2301-2312 were fixed the same day before anything else was run.
    (2101, 960, 540, 0.05, 2, None, True),
    (2102, 960, 540, 0.03, 2, "case_00007", True),
    (2103, 960, 540, 0.08, 2, None, False),
    (2104, 480, 270, 0.10, 2, None, True),
    (2105, 480, 270, 0.05, 2, "case_00045", True),
    (2106, 480, 270, 0.03, 2, None, True),
    (2107, 480, 270, 0.08, 2, "case_00090", False),
    (2108, 480, 270, 0.05, 4, None, True),
    (2109, 960, 540, 0.02, 2, None, True),
    (2110, 480, 270, 0.10, 2, "case_00144", True),
    (2111, 960, 540, 0.10, 2, None, True),
    (2112, 480, 270, 0.03, 4, None, True),
    # The ninth test set: run once on 2026-12-05 (ninth session) with that session's final
    # fit (the placement refining 12 candidates), so it joined the tuning set; 2501-2512 were
    # fixed the same day before anything else was run.
    (2301, 960, 540, 0.05, 2, None, True),
    (2302, 960, 540, 0.03, 2, "case_00051", True),
    (2303, 960, 540, 0.10, 2, None, False),
    (2304, 480, 270, 0.08, 2, None, True),
    (2305, 480, 270, 0.03, 2, "case_00083", True),
    (2306, 480, 270, 0.05, 2, None, True),
    (2307, 480, 270, 0.10, 2, "case_00109", False),
    (2308, 480, 270, 0.05, 4, None, True),
    (2309, 960, 540, 0.02, 2, None, True),
    (2310, 480, 270, 0.08, 2, "case_00174", True),
    (2311, 960, 540, 0.08, 2, None, True),
    (2312, 480, 270, 0.03, 4, None, False),
    # The tenth test set: run once on 2026-12-05 (tenth session) with that session's final
    # fit (the stereo patch following the model's surface, channels weighed by the tissue's
    # squared mean colour), so it joined the tuning set; 2601-2612 were fixed the same day before anything
    # else was run. The shape set's 30 patients are all in use: 2601-2612 take the three
    # patients of ../shared/data/kits19 instead.
    (2501, 960, 540, 0.05, 2, None, True),
    (2502, 960, 540, 0.03, 2, "case_00117", True),
    (2503, 960, 540, 0.08, 2, None, False),
    (2504, 480, 270, 0.10, 2, None, True),
    (2505, 480, 270, 0.03, 2, "case_00009", True),
    (2506, 480, 270, 0.05, 2, None, True),
    (2507, 480, 270, 0.08, 2, "case_00201", False),
    (2508, 480, 270, 0.05, 4, None, True),
    (2509, 960, 540, 0.02, 2, None, True),
    (2510, 480, 270, 0.10, 2, "case_00013", True),
    (2511, 960, 540, 0.10, 2, None, True),
    (2512, 480, 270, 0.03, 4, None, False),
    # The eleventh test set: run once on 2026-12-05 (tenth session) with that session's final
    # fit (after the review's range check), so it joined the tuning set; 2801-2812 were fixed
    # the same day before anything else was run. Every patient is in the tuning set now:
    # 2801-2812 draw new rigs, looks, deformations and noise around four of them.
    (2601, 960, 540, 0.05, 2, None, True),
    (2602, 960, 540, 0.03, 2, "case_00003", True),
    (2603, 960, 540, 0.08, 2, None, False),
    (2604, 480, 270, 0.10, 2, None, True),
    (2605, 480, 270, 0.03, 2, "case_00010", True),
    (2606, 480, 270, 0.05, 2, None, True),
    (2607, 480, 270, 0.08, 2, "case_00170", False),
    (2608, 480, 270, 0.05, 4, None, True),
    (2609, 960, 540, 0.02, 2, None, True),
    (2610, 480, 270, 0.10, 2, None, True),
    (2611, 960, 540, 0.10, 2, None, True),
    (2612, 480, 270, 0.03, 4, None, False),
    # The twelfth test set: run once on 2026-12-06 (eleventh session) with that session's final
    # fit (camera correction kept on three frames after a marked zoom instead of one), so it
    # joined the tuning set; 2901-2912 were fixed the same day before anything else was run.
    (2801, 960, 540, 0.05, 2, None, True),
    (2802, 960, 540, 0.03, 2, "case_00023", True),
    (2803, 960, 540, 0.08, 2, None, False),
    (2804, 480, 270, 0.10, 2, None, True),
    (2805, 480, 270, 0.03, 2, "case_00170", True),
    (2806, 480, 270, 0.05, 2, None, True),
    (2807, 480, 270, 0.08, 2, "case_00003", False),
    (2808, 480, 270, 0.05, 4, None, True),
    (2809, 960, 540, 0.02, 2, None, True),
    (2810, 480, 270, 0.10, 2, "case_00010", True),
    (2811, 960, 540, 0.10, 2, None, True),
    (2812, 480, 270, 0.03, 4, None, False),
    # The thirteenth test set: run once on 2026-12-06 (twelfth session) with that session's
    # final fit (fx's step carrying fy and k1; stereo matching on smoothed images), so it
    # joined the tuning set; 3101-3112 were fixed the same day before anything else was run.
    (2901, 960, 540, 0.05, 2, None, True),
    (2902, 960, 540, 0.03, 2, "case_00010", True),
    (2903, 960, 540, 0.08, 2, None, False),
    (2904, 480, 270, 0.10, 2, None, True),
    (2905, 480, 270, 0.03, 2, "case_00023", True),
    (2906, 480, 270, 0.05, 2, None, True),
    (2907, 480, 270, 0.08, 2, "case_00170", False),
    (2908, 480, 270, 0.05, 4, None, True),
    (2909, 960, 540, 0.02, 2, None, True),
    (2910, 480, 270, 0.10, 2, "case_00003", True),
    (2911, 960, 540, 0.10, 2, None, True),
    (2912, 480, 270, 0.03, 4, None, False),
    # The fourteenth: run once on 2026-12-06 (thirteenth session) with the fit unchanged from
    # the twelfth (LSC Dice 0.951, hidden 1.76 / 5.37 mm, fx 0.98 %, k1 0.027), so it joined
    # the tuning set; 3301-3312 were fixed the same day before anything else was run.
    (3101, 960, 540, 0.05, 2, None, True),
    (3102, 960, 540, 0.03, 2, "case_00023", True),
    (3103, 960, 540, 0.08, 2, None, False),
    (3104, 480, 270, 0.10, 2, None, True),
    (3105, 480, 270, 0.03, 2, "case_00170", True),
    (3106, 480, 270, 0.05, 2, None, True),
    (3107, 480, 270, 0.08, 2, "case_00003", False),
    (3108, 480, 270, 0.05, 4, None, True),
    (3109, 960, 540, 0.02, 2, None, True),
    (3110, 480, 270, 0.10, 2, "case_00010", True),
    (3111, 960, 540, 0.10, 2, None, True),
    (3112, 480, 270, 0.03, 4, None, False),
    # The fifteenth: run once on 2026-12-06 (fourteenth session) with that session's final
    # build (a given initial pose polished; LSC Dice 0.956, hidden 2.19 / 7.42 mm, fx 0.62 %,
    # k1 0.018), so it joined the tuning set; 3501-3512 were fixed the same day before anything
    # else was run.
    (3301, 960, 540, 0.05, 2, None, True),
    (3302, 960, 540, 0.03, 2, "case_00003", True),
    (3303, 960, 540, 0.08, 2, None, False),
    (3304, 480, 270, 0.10, 2, None, True),
    (3305, 480, 270, 0.03, 2, "case_00010", True),
    (3306, 480, 270, 0.05, 2, None, True),
    (3307, 480, 270, 0.08, 2, "case_00023", False),
    (3308, 480, 270, 0.05, 4, None, True),
    (3309, 960, 540, 0.02, 2, None, True),
    (3310, 480, 270, 0.10, 2, "case_00170", True),
    (3311, 960, 540, 0.10, 2, None, True),
    (3312, 480, 270, 0.03, 4, None, False),
    # The sixteenth: run once on 2026-12-07 (twenty-second session) with that session's build
    # (LSC Dice 0.955, hidden 1.71 / 6.13 mm, fx 0.74 %, k1 0.021), so it joined the tuning
    # set; 3701-3712 were fixed the same day before anything else was run.
    (3501, 960, 540, 0.05, 2, None, True),
    (3502, 960, 540, 0.03, 2, "case_00010", True),
    (3503, 960, 540, 0.08, 2, None, False),
    (3504, 480, 270, 0.10, 2, None, True),
    (3505, 480, 270, 0.03, 2, "case_00023", True),
    (3506, 480, 270, 0.05, 2, None, True),
    (3507, 480, 270, 0.08, 2, "case_00170", False),
    (3508, 480, 270, 0.05, 4, None, True),
    (3509, 960, 540, 0.02, 2, None, True),
    (3510, 480, 270, 0.10, 2, "case_00003", True),
    (3511, 960, 540, 0.10, 2, None, True),
    (3512, 480, 270, 0.03, 4, None, False),
    # The seventeenth: run once on 2026-12-07 (twenty-second session) with the same build as the
    # sixteenth (LSC Dice 0.961, hidden 1.79 / 3.99 mm, fx 0.90 %, k1 0.014), so it joined the
    # tuning set; 3901-3912 had been fixed before it was run.
    (3701, 960, 540, 0.05, 2, None, True),
    (3702, 960, 540, 0.03, 2, "case_00170", True),
    (3703, 960, 540, 0.08, 2, None, False),
    (3704, 480, 270, 0.10, 2, None, True),
    (3705, 480, 270, 0.03, 2, "case_00003", True),
    (3706, 480, 270, 0.05, 2, None, True),
    (3707, 480, 270, 0.08, 2, "case_00010", False),
    (3708, 480, 270, 0.05, 4, None, True),
    (3709, 960, 540, 0.02, 2, None, True),
    (3710, 480, 270, 0.10, 2, "case_00023", True),
    (3711, 960, 540, 0.10, 2, None, True),
    (3712, 480, 270, 0.03, 4, None, False),
    # The eighteenth: run once on 2026-12-07 (twenty-third session) with that session's build
    # (tracked-frame pose damping 0.3; LSC Dice 0.964, hidden 1.37 / 2.81 mm, fx 0.97 %, k1
    # 0.019), so it joined the tuning set; 4101-4112 had been fixed before it was run.
    (3901, 960, 540, 0.05, 2, None, True),
    (3902, 960, 540, 0.03, 2, "case_00023", True),
    (3903, 960, 540, 0.08, 2, None, False),
    (3904, 480, 270, 0.10, 2, None, True),
    (3905, 480, 270, 0.03, 2, "case_00010", True),
    (3906, 480, 270, 0.05, 2, None, True),
    (3907, 480, 270, 0.08, 2, "case_00003", False),
    (3908, 480, 270, 0.05, 4, None, True),
    (3909, 960, 540, 0.02, 2, None, True),
    (3910, 480, 270, 0.10, 2, "case_00170", True),
    (3911, 960, 540, 0.10, 2, None, True),
    (3912, 480, 270, 0.03, 4, None, False),
    # The nineteenth: run once on 2026-12-07 (twenty-third session) with that session's final
    # build (silhouette-centred placement, 60 x 12 lattice; LSC Dice 0.960, hidden 1.36 / 4.44
    # mm, fx 0.87 %, k1 0.013, placement min 0.798), so it joined the tuning set; 4301-4312
    # had been fixed before it was run.
    (4101, 960, 540, 0.05, 2, None, True),
    (4102, 960, 540, 0.03, 2, "case_00003", True),
    (4103, 960, 540, 0.08, 2, None, False),
    (4104, 480, 270, 0.10, 2, None, True),
    (4105, 480, 270, 0.03, 2, "case_00170", True),
    (4106, 480, 270, 0.05, 2, None, True),
    (4107, 480, 270, 0.08, 2, "case_00010", False),
    (4108, 480, 270, 0.05, 4, None, True),
    (4109, 960, 540, 0.02, 2, None, True),
    (4110, 480, 270, 0.10, 2, "case_00023", True),
    (4111, 960, 540, 0.10, 2, None, True),
    (4112, 480, 270, 0.03, 4, None, False),
    # The twentieth: run once on 2026-12-07 (twenty-fourth session) with that session's build
    # (at most 32 lines per structure and view; LSC Dice 0.946, hidden 1.63 / 4.91 mm, fx
    # 0.71 %, k1 0.021, LS median 10.3 ms at 960x540, placement min 0.889), so it joined the
    # tuning set; 4501-4512 had been fixed before it was run.
    (4301, 960, 540, 0.05, 2, None, True),
    (4302, 960, 540, 0.03, 2, "case_00010", True),
    (4303, 960, 540, 0.08, 2, None, False),
    (4304, 480, 270, 0.10, 2, None, True),
    (4305, 480, 270, 0.03, 2, "case_00023", True),
    (4306, 480, 270, 0.05, 2, None, True),
    (4307, 480, 270, 0.08, 2, "case_00170", False),
    (4308, 480, 270, 0.05, 4, None, True),
    (4309, 960, 540, 0.02, 2, None, True),
    (4310, 480, 270, 0.10, 2, "case_00003", True),
    (4311, 960, 540, 0.10, 2, None, True),
    (4312, 480, 270, 0.03, 4, None, False),
    # The twenty-first: run once on 2026-12-07 (twenty-fifth session) with the twenty-fourth
    # session's build, unchanged (LSC Dice 0.958, hidden 2.11 / 5.43 mm, fx 0.91 %, k1 0.023,
    # LS median 13.3 ms at 960x540 on a machine running ~13 % slower than the day before,
    # placement min 0.949), so it joined the tuning set; 4701-4712 had been fixed before it
    # was run.
    (4501, 960, 540, 0.05, 2, None, True),
    (4502, 960, 540, 0.03, 2, "case_00170", True),
    (4503, 960, 540, 0.08, 2, None, False),
    (4504, 480, 270, 0.10, 2, None, True),
    (4505, 480, 270, 0.03, 2, "case_00023", True),
    (4506, 480, 270, 0.05, 2, None, True),
    (4507, 480, 270, 0.08, 2, "case_00003", False),
    (4508, 480, 270, 0.05, 4, None, True),
    (4509, 960, 540, 0.02, 2, None, True),
    (4510, 480, 270, 0.10, 2, "case_00010", True),
    (4511, 960, 540, 0.10, 2, None, True),
    (4512, 480, 270, 0.03, 4, None, False),
    # The twenty-second: run once on 2026-12-07 (twenty-fifth session) with that session's
    # build (near ties in the placement settled by the first frame's fit; LSC Dice 0.965,
    # hidden 1.91 / 7.16 mm, fx 0.97 %, k1 0.016, placement min 0.962; its timings were taken
    # beside a CI run), so it joined the tuning set; 4901-4912 had been fixed before it was run.
    (4701, 960, 540, 0.05, 2, None, True),
    (4702, 960, 540, 0.03, 2, "case_00023", True),
    (4703, 960, 540, 0.08, 2, None, False),
    (4704, 480, 270, 0.10, 2, None, True),
    (4705, 480, 270, 0.03, 2, "case_00010", True),
    (4706, 480, 270, 0.05, 2, None, True),
    (4707, 480, 270, 0.08, 2, "case_00170", False),
    (4708, 480, 270, 0.05, 4, None, True),
    (4709, 960, 540, 0.02, 2, None, True),
    (4710, 480, 270, 0.10, 2, "case_00003", True),
    (4711, 960, 540, 0.10, 2, None, True),
    (4712, 480, 270, 0.03, 4, None, False),
    # The twenty-third: run once on 2026-12-07 (twenty-sixth session) with that session's
    # first build (the views' probabilities one per core; trajectories as before; LSC Dice
    # 0.957, hidden 1.30 / 3.96 mm, fx 0.67 %, k1 0.014, placement min 0.766 on 4905, LS
    # median 13.0 ms at 960x540), so it joined the tuning set; 5101-5112 had been fixed before
    # it was run.
    (4901, 960, 540, 0.05, 2, None, True),
    (4902, 960, 540, 0.03, 2, "case_00003", True),
    (4903, 960, 540, 0.08, 2, None, False),
    (4904, 480, 270, 0.10, 2, None, True),
    (4905, 480, 270, 0.03, 2, "case_00170", True),
    (4906, 480, 270, 0.05, 2, None, True),
    (4907, 480, 270, 0.08, 2, "case_00023", False),
    (4908, 480, 270, 0.05, 4, None, True),
    (4909, 960, 540, 0.02, 2, None, True),
    (4910, 480, 270, 0.10, 2, "case_00010", True),
    (4911, 960, 540, 0.10, 2, None, True),
    (4912, 480, 270, 0.03, 4, None, False),
]
# The twenty-fourth, fixed on 2026-12-07 (twenty-fifth session) before 4901-4912 were run.
TEST = [
    (5101, 960, 540, 0.05, 2, None, True),
    (5102, 960, 540, 0.03, 2, "case_00010", True),
    (5103, 960, 540, 0.08, 2, None, False),
    (5104, 480, 270, 0.10, 2, None, True),
    (5105, 480, 270, 0.03, 2, "case_00003", True),
    (5106, 480, 270, 0.05, 2, None, True),
    (5107, 480, 270, 0.08, 2, "case_00170", False),
    (5108, 480, 270, 0.05, 4, None, True),
    (5109, 960, 540, 0.02, 2, None, True),
    (5110, 480, 270, 0.10, 2, "case_00023", True),
    (5111, 960, 540, 0.10, 2, None, True),
    (5112, 480, 270, 0.03, 4, None, False),
]
# The twenty-fifth, fixed on 2026-12-07 (twenty-sixth session) before 5101-5112 were run:
# the next test set once those have been reported and joined the tuning set.
NEXT_TEST = [
    (5301, 960, 540, 0.05, 2, None, True),
    (5302, 960, 540, 0.03, 2, "case_00170", True),
    (5303, 960, 540, 0.08, 2, None, False),
    (5304, 480, 270, 0.10, 2, None, True),
    (5305, 480, 270, 0.03, 2, "case_00023", True),
    (5306, 480, 270, 0.05, 2, None, True),
    (5307, 480, 270, 0.08, 2, "case_00010", False),
    (5308, 480, 270, 0.05, 4, None, True),
    (5309, 960, 540, 0.02, 2, None, True),
    (5310, 480, 270, 0.10, 2, "case_00003", True),
    (5311, 960, 540, 0.10, 2, None, True),
    (5312, 480, 270, 0.03, 4, None, False),
]
FRAMES = 40
# The kind of tuning scene the test sets fail on most (480x270, noise 0.08-0.10, a zoom: each
# set's x04 and x10 seeds), for trying a change where it matters before the whole tuning set.
HARD = [s for s in TUNING if (s[1], s[2]) == (480, 270) and s[3] >= 0.08 and s[6]]


def run(args):
    r = subprocess.run(args, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"{' '.join(args)} failed ({r.returncode}):\n{r.stderr[-2000:]}")
    return r


def make_scene(spec, work, frames=FRAMES):
    """The widened phantom of `spec` (seed, width, height, noise, views, KiTS case, zoom) in
    `work`, made once (also used by benches/hidden_region_coverage.py)."""
    seed, w, h, noise, views, case, zoom = spec
    out = os.path.join(work, f"scene-{seed}")
    if os.path.exists(os.path.join(out, "scene.json")):
        return out
    args = [BIN, "synth", "--out", out, "--seed", str(seed), "--frames", str(frames),
            "--width", str(w), "--height", str(h), "--noise", str(noise), "--views", str(views),
            "--vary-rig", "--vary-look"]
    if not zoom:
        args.append("--no-zoom")
    if case:
        meshes = os.path.join(work, f"ct-{case}")
        if not os.path.exists(meshes):
            run([BIN, "import-ct", kits_volume(case),
                 "--out", meshes])
        args += ["--meshes", meshes]
    run(args)
    return out


def frame_pairs(out, scene):
    """Each fitted frame of `out` beside the scene's truth for the same frame number."""
    gt = {f["frame"]: f for f in json.load(open(os.path.join(scene, "gt", "trajectory.json")))["frames"]}
    est = json.load(open(os.path.join(out, "trajectory.json")))["frames"]
    return [(e, gt[e["frame"]]) for e in est if e["frame"] in gt]


def camera_errors(pairs):
    fx, pp, k1 = [], [], []
    for a, b in pairs:
        for x, y in zip(a["cameras"], b["cameras"]):
            fx.append(abs(x["fx"] / y["fx"] - 1) * 100)
            pp.append(max(abs(x["cx"] - y["cx"]), abs(x["cy"] - y["cy"])))
            k1.append(abs(x["k1"] - y["k1"]))
    return statistics.mean(fx), max(fx), statistics.mean(pp), max(pp), max(k1)


def track(scene, mode, work):
    out = os.path.join(work, f"out-{os.path.basename(scene)}-{mode}")
    run([BIN, "track", scene, "--out", out, "--mode", mode])
    m = json.load(open(os.path.join(out, "metrics.json")))
    return out, m, m["dice"]["mean"], None


def without_initial_pose(scene):
    """The scene's scene.json without its initial_pose, beside it: placed automatically."""
    d = json.load(open(os.path.join(scene, "scene.json")))
    d.pop("initial_pose", None)
    path = os.path.join(scene, "scene-noinit.json")
    json.dump(d, open(path, "w"))
    return path


def row(spec, work):
    scene = make_scene(spec, work)
    seed, w, h, noise, views, case, zoom = spec
    what = f"{seed}: {w}x{h}, noise {noise:.2f}, {views} views" + (f", {case}" if case else "") \
        + (", zoom" if zoom else "")
    res = {}
    for mode in ["LS", "LSC"]:
        res[mode] = track(scene, mode, work)
    # From no initial pose at all: the automatic placement, then LSC.
    out = os.path.join(work, f"out-{os.path.basename(scene)}-LSC-noinit")
    run([BIN, "track", without_initial_pose(scene), "--out", out, "--mode", "LSC"])
    res["noinit"] = json.load(open(os.path.join(out, "metrics.json")))["dice"]
    return what, scene, res


def hidden_mm(m):
    h = m.get("hidden") or {}
    vals = [v.get("centroid_error_mm_mean") for v in h.values() if isinstance(v, dict)]
    vals = [v for v in vals if v is not None]
    mx = [v.get("centroid_error_mm_max") for v in h.values() if isinstance(v, dict)]
    mx = [v for v in mx if v is not None]
    return (statistics.mean(vals) if vals else None, max(mx) if mx else None)


def hidden_parts(pairs, hidden):
    """Where the hidden structures' centroid error comes from, mean over fitted frames (mm):
    the visible kidney's own centroid error along camera 0's axis (signed: + too deep) and
    across it, and what is left once the kidney's error is taken out (the hidden structure
    misplaced inside the kidney: shape and rotation)."""
    depth, across, relative = [], [], []
    for e, g in pairs:
        if e.get("lost") or "kidney" not in e["centroids"] or "kidney" not in g["centroids"]:
            continue
        k = [a - b for a, b in zip(e["centroids"]["kidney"], g["centroids"]["kidney"])]
        for h in hidden:
            if h not in e["centroids"] or h not in g["centroids"]:
                continue
            t = [a - b for a, b in zip(e["centroids"][h], g["centroids"][h])]
            depth.append(k[2])
            across.append(math.hypot(k[0], k[1]))
            relative.append(math.dist(t, k))
    if not depth:
        return None
    return statistics.mean(depth), statistics.mean(across), statistics.mean(relative)


def table(name, specs, work):
    print(f"\n{name} set ({len(specs)} scenes, {FRAMES} frames each)\n")
    print("| scene | LS Dice | LSC Dice | hidden LS / LSC mean (max) mm | LSC fx err mean (max) % "
          "| LSC pp err mean (max) px | LSC k1 err max | LS / LSC ms per frame "
          "| LSC without initial pose: frame-0 / mean Dice "
          "| LSC hidden error's parts: kidney depth (+ deep) / kidney across / hidden in kidney mm |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    agg = {"dice": [], "hidden": [], "hidden_max": [], "fx": [], "k1": [], "ms_ls": [], "ms_lsc": [],
           "ms_ls_960": [], "ms_lsc_960": [], "noinit0": [], "depth": [], "across": [],
           "relative": []}
    for spec in specs:
        what, scene, res = row(spec, work)
        (o_ls, m_ls, d_ls, _), (o_lsc, m_lsc, d_lsc, _) = res["LS"], res["LSC"]
        h_ls, hmax_ls = hidden_mm(m_ls)
        h_lsc, hmax_lsc = hidden_mm(m_lsc)
        pairs = frame_pairs(o_lsc, scene)
        fx, fxmax, pp, ppmax, k1 = camera_errors(pairs)
        ms_ls = m_ls["timing"]["ms_per_frame"]["median"]
        ms_lsc = m_lsc["timing"]["ms_per_frame"]["median"]
        hid = "–" if h_ls is None else f"{h_ls:.2f} / {h_lsc:.2f} ({hmax_lsc:.2f})"
        ni = res["noinit"]
        hidden = [k for k, v in (m_lsc.get("hidden") or {}).items() if isinstance(v, dict)]
        parts = hidden_parts(pairs, hidden)
        split = "–" if parts is None else f"{parts[0]:+.2f} / {parts[1]:.2f} / {parts[2]:.2f}"
        if parts is not None:
            for key, v in zip(["depth", "across", "relative"], parts):
                agg[key].append(v)
        print(f"| {what} | {d_ls:.3f} | {d_lsc:.3f} | {hid} | {fx:.2f} ({fxmax:.2f}) "
              f"| {pp:.2f} ({ppmax:.2f}) | {k1:.3f} | {ms_ls:.1f} / {ms_lsc:.1f} "
              f"| {ni['per_frame'][0]:.3f} / {ni['mean']:.3f} | {split} |", flush=True)
        agg["noinit0"].append(ni["per_frame"][0])
        agg["dice"].append(d_lsc)
        if h_lsc is not None:
            agg["hidden"].append(h_lsc)
            agg["hidden_max"].append(hmax_lsc)
        agg["fx"].append(fx)
        agg["k1"].append(k1)
        agg["ms_ls"].append(ms_ls)
        agg["ms_lsc"].append(ms_lsc)
        if (spec[1], spec[2]) == (960, 540):
            agg["ms_ls_960"].append(ms_ls)
            agg["ms_lsc_960"].append(ms_lsc)
    print(f"\n{name}: LSC Dice mean {statistics.mean(agg['dice']):.3f}; hidden centroid mean "
          f"{statistics.mean(agg['hidden']) if agg['hidden'] else float('nan'):.2f} mm, worst "
          f"{max(agg['hidden_max']) if agg['hidden_max'] else float('nan'):.2f} mm; fx error mean "
          f"{statistics.mean(agg['fx']):.2f} %; k1 error max {max(agg['k1']):.3f}; median ms per "
          f"frame LS {statistics.median(agg['ms_ls']):.1f}, LSC {statistics.median(agg['ms_lsc']):.1f}; "
          f"placed automatically, frame-0 Dice min {min(agg['noinit0']):.3f}")
    if agg["ms_ls_960"]:
        # Issue 14's speed goal is at 960x540 (LS <= 10, LSC <= 15 ms per frame): the median
        # over those scenes of each scene's median, and how many scenes' own medians exceed it.
        ls, lsc = agg["ms_ls_960"], agg["ms_lsc_960"]
        print(f"{name}: 960x540 scenes ({len(ls)}): median ms per frame LS "
              f"{statistics.median(ls):.1f} ({sum(v > 10 for v in ls)} above 10), LSC "
              f"{statistics.median(lsc):.1f} ({sum(v > 15 for v in lsc)} above 15)")
    if agg["depth"]:
        print(f"{name}: the LSC hidden error's parts, mean over scenes: kidney depth "
              f"{statistics.mean(agg['depth']):+.2f} mm (mean |.| "
              f"{statistics.mean(abs(v) for v in agg['depth']):.2f}), kidney across "
              f"{statistics.mean(agg['across']):.2f} mm, hidden in kidney "
              f"{statistics.mean(agg['relative']):.2f} mm")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--set", default="both", choices=["tuning", "test", "both", "hard"])
    ap.add_argument("--keep", help="folder for scenes and outputs (reused between runs)")
    a = ap.parse_args()
    if not os.path.exists(BIN):
        sys.exit("build first: cargo build --release")
    work = a.keep or tempfile.mkdtemp(prefix="fit-heldout-")
    os.makedirs(work, exist_ok=True)
    if a.set in ("tuning", "both"):
        table("tuning", TUNING, work)
    if a.set in ("test", "both"):
        table("test", TEST, work)
    if a.set == "hard":
        table("hard tuning", HARD, work)


if __name__ == "__main__":
    main()
