#!/usr/bin/env python3
"""Is the hidden tumour's 95 % region calibrated (issue 16)? Widened phantoms with truth are
tracked as a user would, and for every frame the true centroid is tested against the sphere
`trajectory.json` gives (`hidden_region`): coverage (share of frames inside, 90-98 % wanted)
and the median radius per mode, on a tuning set and a held-out test set.

    cargo build --release && python3 benches/hidden_region_coverage.py [--set tuning|test|both]
        [--modes LSC,LS,L,R] [--keep DIR] [--calibrate]

`--calibrate` (tuning set only) also searches the constants the images cannot know: each
frame's covariance as the tracker wrote it is taken apart into its data part (the fit's own
information carried to the centroid) with the constants it ran with (metrics.json's config), and
rebuilt for each candidate: the covariance scale s, the model error e, its growth k with the rim
the fit leaves unexplained beyond a floor ρ₀ and q with the fit's confidence short of c₀, the
depth after a corrected zoom d_c (LSC), after a zoom the pose alone followed d_u and its share u
of the depth the fit moved since the zoom began (LS); on the lost frames the growth g. With
numpy (`calibrate_joint`), only candidates whose region holds 93-97 % of the tuning frames with
and without a zoom's depth term, and with the fit's confidence under 0.7 and not, qualify in
each mode; they are judged as a held-out set will judge them: on 2000 sets of 16 tuning scenes
drawn like the test set (per test scene, a tuning scene of its kind), the share of sets whose
coverage is 90-98 % with a median radius of at most 4 mm, the smaller share of the two modes,
ties to the smaller radius (a set's frames miss scene by scene, so pooled coverage says too
little; about 18 minutes on one core). Without numpy, the staged search: the smallest median
radius holding 95 % of the pooled frames, s, e, k, d_c on LSC, then LS's terms (ρ₀, q and c₀ as
configured, no balance).
The constants are printed, to be made the defaults. The seeds below were fixed before any constant was chosen; the test set is never used to choose. Not part
of CI: about half a minute per scene and mode on 2 cores.
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
# The fourth (session 2026-12-03, after the shape prior was made 64x firmer): `--calibrate` on
# the 24 tuning scenes chose s 1, e 1.25, d_c 0.005, g 3 (LSC 95.1 % at 4.77 mm against the
# constants before, 94.6 % at 4.79 mm), but on 801-812 these held the truth in 89.2 % (LSC) /
# 94.4 % (LS) of the frames, so they were not taken: a choice 801-812 informed, so they joined
# the tuning set too, and 1001-1012 were fixed as the test set before it was run. With the
# constants before, the 36 tuning scenes gave LSC 92.8 % (and 1001-1012, run once with them,
# 86.5 %), so the constants were recalibrated on the 36 alone (s 8, e 1.5, k 1, d_c 0.01,
# u 0.75, g 2; 1001-1012 with them: LSC 88.2 %, LS 89.9 %).
# The fifth (session 2026-12-04, fifth): 1001-1012 joined the tuning set (48 scenes) and
# 1601-1616 were fixed first; the joint search chose s 16, e 0.5, k 2, d_c 0.01, u 0.75, g 0.5
# (tuning LSC 96.1 % at 4.97 mm, LS 96.1 % at 5.50; test LSC 93.8 % at 4.73, LS 93.8 % at 5.21).
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
    # The fifth: 1001-1012 were reported with the constants of 2026-12-03, so they joined the
    # tuning set when the constants were recalibrated after the fit's stereo weight changed
    # (2026-12-04, fifth session); 1601-1616 were fixed as the test set before anything was run.
    (1001, 480, 270, 0.03, 2, None, True),
    (1002, 480, 270, 0.05, 2, None, True),
    (1003, 640, 360, 0.03, 2, None, True),
    (1004, 480, 270, 0.05, 2, None, False),
    (1005, 960, 540, 0.04, 2, None, True),
    (1006, 480, 270, 0.03, 4, None, True),
    (1007, 640, 360, 0.02, 2, None, True),
    (1008, 480, 270, 0.04, 2, "case_00023", True),
    (1009, 960, 540, 0.02, 2, None, True),
    (1010, 480, 270, 0.05, 2, None, True),
    (1011, 640, 360, 0.03, 4, None, True),
    (1012, 480, 270, 0.03, 2, None, False),
    # The sixth (session 2026-12-05, seventh): the phantom had drawn tool shafts beyond the
    # lens model's fold back into the image (black wedges over the organ where k1 and k2 are
    # both negative); with that fixed every scene was made again, 1601-1616 (reported once)
    # joined the tuning set, and 1801-1816 were fixed as the test set before anything was run.
# `--calibrate` on the 64 then chose s 0.25, e 1.5, k 0, d_c 0.015, u 1, g 8 (LSC 95.4 % at
# 5.54 mm, LS 95.0 % at 4.21 mm); with the constants kept LSC held 95.2 % at 4.88 mm and LS
# 94.9 % at 5.38 mm, so they were kept: the trade widens the region of LSC, the mode for zooms.
    (1601, 480, 270, 0.03, 2, None, True),
    (1602, 480, 270, 0.05, 2, None, True),
    (1603, 640, 360, 0.04, 2, None, True),
    (1604, 480, 270, 0.02, 2, None, False),
    (1605, 960, 540, 0.03, 2, None, True),
    (1606, 480, 270, 0.04, 4, None, True),
    (1607, 640, 360, 0.05, 2, None, False),
    (1608, 480, 270, 0.03, 2, "case_00023", True),
    (1609, 960, 540, 0.05, 2, None, True),
    (1610, 480, 270, 0.05, 2, None, True),
    (1611, 640, 360, 0.02, 4, None, True),
    (1612, 480, 270, 0.04, 2, None, False),
    (1613, 480, 270, 0.02, 2, None, True),
    (1614, 640, 360, 0.03, 2, None, True),
    (1615, 960, 540, 0.04, 2, None, False),
    (1616, 480, 270, 0.05, 4, None, True),
    # The seventh (session 2026-12-05, eighth): 1801-1816 (reported once, with the constants
    # kept) joined the tuning set before the first frame's pose damping changed (0.1 -> the
    # fit's new default), and 2001-2016 were fixed as the test set before anything was run.
    (1801, 480, 270, 0.03, 2, None, True),
    (1802, 480, 270, 0.05, 2, None, True),
    (1803, 640, 360, 0.04, 2, None, True),
    (1804, 480, 270, 0.02, 2, None, False),
    (1805, 960, 540, 0.03, 2, None, True),
    (1806, 480, 270, 0.04, 4, None, True),
    (1807, 640, 360, 0.05, 2, None, False),
    (1808, 480, 270, 0.03, 2, "case_00023", True),
    (1809, 960, 540, 0.05, 2, None, True),
    (1810, 480, 270, 0.05, 2, None, True),
    (1811, 640, 360, 0.02, 4, None, True),
    (1812, 480, 270, 0.04, 2, None, False),
    (1813, 480, 270, 0.02, 2, None, True),
    (1814, 640, 360, 0.03, 2, None, True),
    (1815, 960, 540, 0.04, 2, None, False),
    (1816, 480, 270, 0.05, 4, None, True),
    # The eighth (same session): 2001-2016 were reported once with the constants chosen on the
    # 80 (s 4, e 0.75, k 2, g 6), so they joined the tuning set; 2201-2216 were fixed as the
    # test set before anything else was run.
    (2001, 480, 270, 0.03, 2, None, True),
    (2002, 480, 270, 0.05, 2, None, True),
    (2003, 640, 360, 0.04, 2, None, True),
    (2004, 480, 270, 0.02, 2, None, False),
    (2005, 960, 540, 0.03, 2, None, True),
    (2006, 480, 270, 0.04, 4, None, True),
    (2007, 640, 360, 0.05, 2, None, False),
    (2008, 480, 270, 0.03, 2, "case_00023", True),
    (2009, 960, 540, 0.05, 2, None, True),
    (2010, 480, 270, 0.05, 2, None, True),
    (2011, 640, 360, 0.02, 4, None, True),
    (2012, 480, 270, 0.04, 2, None, False),
    (2013, 480, 270, 0.02, 2, None, True),
    (2014, 640, 360, 0.03, 2, None, True),
    (2015, 960, 540, 0.04, 2, None, False),
    (2016, 480, 270, 0.05, 4, None, True),
    # The ninth (session 2026-12-05, ninth): `--calibrate` on the 96 (s 2, e 0, k 2, d_c 0.015,
    # u 1.25: LSC 95.5 % at 4.69 mm, LS 95.1 % at 3.96) traded LSC's region for LS's against
    # the constants kept (LSC 95.3 % at 4.23, LS 96.8 % at 4.37) and was not taken; 2201-2216
    # were reported once with the constants kept (LSC 95.6 % at 4.20, LS 95.6 % at 4.28), so
    # they joined the tuning set; 2401-2416 were fixed as the test set before anything else.
    (2201, 480, 270, 0.03, 2, None, True),
    (2202, 480, 270, 0.05, 2, None, True),
    (2203, 640, 360, 0.04, 2, None, True),
    (2204, 480, 270, 0.02, 2, None, False),
    (2205, 960, 540, 0.03, 2, None, True),
    (2206, 480, 270, 0.04, 4, None, True),
    (2207, 640, 360, 0.05, 2, None, False),
    (2208, 480, 270, 0.03, 2, "case_00023", True),
    (2209, 960, 540, 0.05, 2, None, True),
    (2210, 480, 270, 0.05, 2, None, True),
    (2211, 640, 360, 0.02, 4, None, True),
    (2212, 480, 270, 0.04, 2, None, False),
    (2213, 480, 270, 0.02, 2, None, True),
    (2214, 640, 360, 0.03, 2, None, True),
    (2215, 960, 540, 0.04, 2, None, False),
    (2216, 480, 270, 0.05, 4, None, True),
    # The tenth (session 2026-12-05, tenth; the stereo patch now following the model's surface):
    # the 112 above gave LSC 95.9 % at 4.30 mm, LS 96.3 % at 4.41 with the constants kept;
    # 2401-2416 were reported once (LSC 100.0 % at 4.27, LS 99.0 % at 4.32: wider than needed
    # there), so they joined the tuning set; 2701-2716 were fixed as the test set before
    # anything else.
    (2401, 480, 270, 0.03, 2, None, True),
    (2402, 480, 270, 0.05, 2, None, True),
    (2403, 640, 360, 0.04, 2, None, True),
    (2404, 480, 270, 0.02, 2, None, False),
    (2405, 960, 540, 0.03, 2, None, True),
    (2406, 480, 270, 0.04, 4, None, True),
    (2407, 640, 360, 0.05, 2, None, False),
    (2408, 480, 270, 0.03, 2, "case_00023", True),
    (2409, 960, 540, 0.05, 2, None, True),
    (2410, 480, 270, 0.05, 2, None, True),
    (2411, 640, 360, 0.02, 4, None, True),
    (2412, 480, 270, 0.04, 2, None, False),
    (2413, 480, 270, 0.02, 2, None, True),
    (2414, 640, 360, 0.03, 2, None, True),
    (2415, 960, 540, 0.04, 2, None, False),
    (2416, 480, 270, 0.05, 4, None, True),
    # The eleventh (session 2026-12-06, eleventh; camera correction kept on three frames after
    # a marked zoom): 2701-2716 were reported once with the constants kept (LSC 96.1 % at
    # 4.39 mm, LS 97.4 % at 4.24 mm), so they joined the tuning set; 3001-3016 were fixed as
    # the test set before anything else.
    (2701, 480, 270, 0.03, 2, None, True),
    (2702, 480, 270, 0.05, 2, None, True),
    (2703, 640, 360, 0.04, 2, None, True),
    (2704, 480, 270, 0.02, 2, None, False),
    (2705, 960, 540, 0.03, 2, None, True),
    (2706, 480, 270, 0.04, 4, None, True),
    (2707, 640, 360, 0.05, 2, None, False),
    (2708, 480, 270, 0.03, 2, "case_00023", True),
    (2709, 960, 540, 0.05, 2, None, True),
    (2710, 480, 270, 0.05, 2, None, True),
    (2711, 640, 360, 0.02, 4, None, True),
    (2712, 480, 270, 0.04, 2, None, False),
    (2713, 480, 270, 0.02, 2, None, True),
    (2714, 640, 360, 0.03, 2, None, True),
    (2715, 960, 540, 0.04, 2, None, False),
    (2716, 480, 270, 0.05, 4, None, True),
    # The twelfth (session 2026-12-06, twelfth; fx's step carrying fy and k1, stereo matching on
    # smoothed images): 3001-3016 were reported once with the constants kept (LSC 98.2 % at
    # 4.32 mm, LS 96.6 % at 4.36), so they joined the tuning set; 3201-3216 were fixed as the
    # test set before anything else.
    (3001, 480, 270, 0.03, 2, None, True),
    (3002, 480, 270, 0.05, 2, None, True),
    (3003, 640, 360, 0.04, 2, None, True),
    (3004, 480, 270, 0.02, 2, None, False),
    (3005, 960, 540, 0.03, 2, None, True),
    (3006, 480, 270, 0.04, 4, None, True),
    (3007, 640, 360, 0.05, 2, None, False),
    (3008, 480, 270, 0.03, 2, "case_00023", True),
    (3009, 960, 540, 0.05, 2, None, True),
    (3010, 480, 270, 0.05, 2, None, True),
    (3011, 640, 360, 0.02, 4, None, True),
    (3012, 480, 270, 0.04, 2, None, False),
    (3013, 480, 270, 0.02, 2, None, True),
    (3014, 640, 360, 0.03, 2, None, True),
    (3015, 960, 540, 0.04, 2, None, False),
    (3016, 480, 270, 0.05, 4, None, True),
    # The thirteenth (session 2026-12-06, thirteenth): `--calibrate` on the 160 above chose
    # s 2, e 0, k 2, d_c 0.01, u 1, g 0.5 (LSC 95.2 % at 3.62 mm, LS 95.7 % at 3.62; the
    # constants before held 98.4 % at 4.31 mm and 97.4 % at 4.33), taken; 3201-3216 were then
    # reported once (LSC 98.7 % at 3.62 mm, LS 92.7 % at 3.59), so they joined the tuning set;
    # 3401-3416 were fixed as the test set before anything else.
    (3201, 480, 270, 0.03, 2, None, True),
    (3202, 480, 270, 0.05, 2, None, True),
    (3203, 640, 360, 0.04, 2, None, True),
    (3204, 480, 270, 0.02, 2, None, False),
    (3205, 960, 540, 0.03, 2, None, True),
    (3206, 480, 270, 0.04, 4, None, True),
    (3207, 640, 360, 0.05, 2, None, False),
    (3208, 480, 270, 0.03, 2, "case_00023", True),
    (3209, 960, 540, 0.05, 2, None, True),
    (3210, 480, 270, 0.05, 2, None, True),
    (3211, 640, 360, 0.02, 4, None, True),
    (3212, 480, 270, 0.04, 2, None, False),
    (3213, 480, 270, 0.02, 2, None, True),
    (3214, 640, 360, 0.03, 2, None, True),
    (3215, 960, 540, 0.04, 2, None, False),
    (3216, 480, 270, 0.05, 4, None, True),
    # The fourteenth (session 2026-12-06, fourteenth; the build of the thirteenth unchanged):
    # 3401-3416 were reported once (LSC 90.4 % at 3.81 mm, LS 94.0 % at 3.80), so they joined
    # the tuning set; 3601-3616 were fixed as the test set before anything else.
    (3401, 640, 360, 0.03, 2, None, True),
    (3402, 480, 270, 0.04, 2, None, True),
    (3403, 960, 540, 0.02, 2, None, True),
    (3404, 480, 270, 0.05, 2, None, False),
    (3405, 480, 270, 0.02, 4, None, True),
    (3406, 640, 360, 0.05, 2, None, True),
    (3407, 480, 270, 0.03, 2, "case_00023", False),
    (3408, 960, 540, 0.04, 2, None, True),
    (3409, 480, 270, 0.03, 2, None, True),
    (3410, 640, 360, 0.04, 4, None, True),
    (3411, 480, 270, 0.05, 2, None, True),
    (3412, 960, 540, 0.03, 2, None, False),
    (3413, 480, 270, 0.04, 2, "case_00023", True),
    (3414, 640, 360, 0.02, 2, None, True),
    (3415, 480, 270, 0.02, 2, None, False),
    (3416, 480, 270, 0.04, 4, None, True),
    # The fifteenth (session 2026-12-06, fourteenth; a given initial pose polished): `--calibrate`
    # on the 192 above chose s 0.25, e 1, k 0, d_c 0.01, u 1.25, g 0.5 (LSC 96.1 % at 3.66 mm,
    # LS 95.1 % at 2.80; the constants before held 98.1 % and 97.2 % at 3.66 / 3.65), taken;
    # 3601-3616 were then reported once (LSC 93.0 % at 3.80 mm, LS 89.6 % at 2.81), so they
    # joined the tuning set; 3801-3816 were fixed as the test set before anything else.
    (3601, 640, 360, 0.03, 2, None, True),
    (3602, 480, 270, 0.04, 2, None, True),
    (3603, 960, 540, 0.02, 2, None, True),
    (3604, 480, 270, 0.05, 2, None, False),
    (3605, 480, 270, 0.02, 4, None, True),
    (3606, 640, 360, 0.05, 2, None, True),
    (3607, 480, 270, 0.03, 2, "case_00023", False),
    (3608, 960, 540, 0.04, 2, None, True),
    (3609, 480, 270, 0.03, 2, None, True),
    (3610, 640, 360, 0.04, 4, None, True),
    (3611, 480, 270, 0.05, 2, None, True),
    (3612, 960, 540, 0.03, 2, None, False),
    (3613, 480, 270, 0.04, 2, "case_00023", True),
    (3614, 640, 360, 0.02, 2, None, True),
    (3615, 480, 270, 0.02, 2, None, False),
    (3616, 480, 270, 0.04, 4, None, True),
    # The sixteenth (session 2026-12-06, fifteenth; a rim floor, and the calibration judged on
    # sets drawn like the test set): `--calibrate` on the 208 above chose s 4, e 0.5, k 4,
    # rho0 0.5, d_c 0.0125, d_u 0.01, u 1, g 0.5 (pooled LSC 94.1 % at 3.68 mm, LS 93.5 % at
    # 3.56; sets like the test set meeting the issue 80 / 79 %), taken; 3801-3816 were then
    # reported once (LSC 88.5 % at 3.63 mm, LS 88.5 % at 3.40: 3804 held none of its frames,
    # its fit 3.9 mm too deep along the ray with a rim under the floor), so they joined the
    # tuning set; 4001-4016 were fixed as the test set before anything else.
    (3801, 640, 360, 0.03, 2, None, True),
    (3802, 480, 270, 0.04, 2, None, True),
    (3803, 960, 540, 0.02, 2, None, True),
    (3804, 480, 270, 0.05, 2, None, False),
    (3805, 480, 270, 0.02, 4, None, True),
    (3806, 640, 360, 0.05, 2, None, True),
    (3807, 480, 270, 0.03, 2, "case_00023", False),
    (3808, 960, 540, 0.04, 2, None, True),
    (3809, 480, 270, 0.03, 2, None, True),
    (3810, 640, 360, 0.04, 4, None, True),
    (3811, 480, 270, 0.05, 2, None, True),
    (3812, 960, 540, 0.03, 2, None, False),
    (3813, 480, 270, 0.04, 2, "case_00023", True),
    (3814, 640, 360, 0.02, 2, None, True),
    (3815, 480, 270, 0.02, 2, None, False),
    (3816, 480, 270, 0.04, 4, None, True),
    # The seventeenth (session 2026-12-06, sixteenth; the region balanced between frames under a
    # zoom and the others): `--calibrate` on the 224 above chose s 4, e 0.875, k 4, rho0 0.6,
    # d_c 0.0075, d_u 0, u 1, g 0.5 (pooled LSC 95.0 % at 3.21 mm, LS 95.3 % at 3.09; sets like
    # the test set meeting the issue 68 / 78 %), taken; 4001-4016 were then reported once (LSC
    # 88.3 % at 3.16 mm, LS 91.4 % at 3.03: 4007, KiTS case_00023 without a zoom, held none of
    # its frames, 4001 3 of 24), so they joined the tuning set; 4201-4216 were fixed as the test
    # set before anything else.
    (4001, 640, 360, 0.03, 2, None, True),
    (4002, 480, 270, 0.04, 2, None, True),
    (4003, 960, 540, 0.02, 2, None, True),
    (4004, 480, 270, 0.05, 2, None, False),
    (4005, 480, 270, 0.02, 4, None, True),
    (4006, 640, 360, 0.05, 2, None, True),
    (4007, 480, 270, 0.03, 2, "case_00023", False),
    (4008, 960, 540, 0.04, 2, None, True),
    (4009, 480, 270, 0.03, 2, None, True),
    (4010, 640, 360, 0.04, 4, None, True),
    (4011, 480, 270, 0.05, 2, None, True),
    (4012, 960, 540, 0.03, 2, None, False),
    (4013, 480, 270, 0.04, 2, "case_00023", True),
    (4014, 640, 360, 0.02, 2, None, True),
    (4015, 480, 270, 0.02, 2, None, False),
    (4016, 480, 270, 0.04, 4, None, True),
    # The eighteenth (the same session): the fit's confidence widens the region, and the
    # calibration also asks frames under and over a confidence of 0.7 to hold 93-97 %;
    # `--calibrate` on the 240 above chose s 1, e 0.875, k 0, q 4, c0 0.8, d_c 0.0075, d_u 0,
    # u 0.75, g 0.5 (pooled LSC 95.3 % at 3.18 mm, LS 95.3 % at 3.06; sets like the test set
    # meeting the issue 61 / 70 %), taken; 4201-4216 were then reported once (LSC 90.9 % at
    # 3.15 mm, LS 91.4 % at 3.21: met; 4207, KiTS case_00023 without a zoom, held none of its
    # frames), so they joined the tuning set; 4401-4416 were fixed as the test set before
    # anything else.
    (4201, 640, 360, 0.03, 2, None, True),
    (4202, 480, 270, 0.04, 2, None, True),
    (4203, 960, 540, 0.02, 2, None, True),
    (4204, 480, 270, 0.05, 2, None, False),
    (4205, 480, 270, 0.02, 4, None, True),
    (4206, 640, 360, 0.05, 2, None, True),
    (4207, 480, 270, 0.03, 2, "case_00023", False),
    (4208, 960, 540, 0.04, 2, None, True),
    (4209, 480, 270, 0.03, 2, None, True),
    (4210, 640, 360, 0.04, 4, None, True),
    (4211, 480, 270, 0.05, 2, None, True),
    (4212, 960, 540, 0.03, 2, None, False),
    (4213, 480, 270, 0.04, 2, "case_00023", True),
    (4214, 640, 360, 0.02, 2, None, True),
    (4215, 480, 270, 0.02, 2, None, False),
    (4216, 480, 270, 0.04, 4, None, True),
]
TEST = [
    (4401, 640, 360, 0.03, 2, None, True),
    (4402, 480, 270, 0.04, 2, None, True),
    (4403, 960, 540, 0.02, 2, None, True),
    (4404, 480, 270, 0.05, 2, None, False),
    (4405, 480, 270, 0.02, 4, None, True),
    (4406, 640, 360, 0.05, 2, None, True),
    (4407, 480, 270, 0.03, 2, "case_00023", False),
    (4408, 960, 540, 0.04, 2, None, True),
    (4409, 480, 270, 0.03, 2, None, True),
    (4410, 640, 360, 0.04, 4, None, True),
    (4411, 480, 270, 0.05, 2, None, True),
    (4412, 960, 540, 0.03, 2, None, False),
    (4413, 480, 270, 0.04, 2, "case_00023", True),
    (4414, 640, 360, 0.02, 2, None, True),
    (4415, 480, 270, 0.02, 2, None, False),
    (4416, 480, 270, 0.04, 4, None, True),
]

FRAMES = 24


def make_scene(spec, work):
    return heldout.make_scene(spec, work, frames=FRAMES)


def track(scene, mode, work, tag):
    out = os.path.join(work, f"track-{tag}-{mode}")
    if not os.path.exists(os.path.join(out, "metrics.json")):
        run([BIN, "track", scene, "--out", out, "--mode", mode])
    with open(os.path.join(out, "metrics.json")) as f:
        metrics = json.load(f)
    with open(os.path.join(out, "trajectory.json")) as f:
        fitted = json.load(f)
    with open(os.path.join(scene, "gt", "trajectory.json")) as f:
        truth = {fr["frame"]: fr for fr in json.load(f)["frames"]}
    with open(os.path.join(scene, "scene.json")) as f:
        changes = json.load(f).get("zoom_changes", [])
    first_zoom = min((c[0] for c in changes), default=None)
    # The fit's own confidence: written with the region since 2026-12-06 (sixteenth session);
    # before, the frame's, which a depth-for-zoom frame reports lowered, and which on a lost
    # frame is the lost fit's while its region (and so its confidence) is the last good one's.
    lowered = metrics.get("config", {}).get("fit", {}).get("tracking", {}).get(
        "depth_zoom_confidence", 0.5)
    zoomed = False
    rows = []
    lost_run = 0
    good_confidence = 1.0
    for fr in fitted["frames"]:
        lost_run = lost_run + 1 if fr.get("lost", False) else 0
        if not lost_run:
            reported = fr.get("confidence")
            reported = 1.0 if reported is None else reported
            if "depth_explains_zoom" in fr.get("warnings", []) and lowered > 0:
                reported /= lowered
            good_confidence = min(1.0, reported)
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
                         "conf": region.get("fit_confidence", good_confidence),
                         "zsd": region.get("zoom_depth_sd", 0.0),
                         "zchange": region.get("zoom_depth_change"),
                         "c": fr["centroids"][name], "zoomed": zoomed})
    config = metrics.get("config", {}).get("fit", {}).get("hidden_region", {})
    for row in rows:
        row["data"] = data_part(row, config)
    return rows, metrics, config


# --- the radius of a Gaussian, as the tracker computes it (fixed normal samples) -------------

_SAMPLES = None


def samples():
    """The tracker's fixed normal samples (`fit::hidden_region::normal_samples`: 8192 triples
    from `rng::Rng` seeded 0x6869_6464_656e, Box-Muller), so that a radius rebuilt here is the
    one the tracker would write (other samples put the 95 % quantile ~2 % elsewhere)."""
    global _SAMPLES
    if _SAMPLES is None:
        mask = (1 << 64) - 1

        def splitmix(z):
            z = (z + 0x9E3779B97F4A7C15) & mask
            x = z
            x = ((x ^ (x >> 30)) * 0xBF58476D1CE4E5B9) & mask
            x = ((x ^ (x >> 27)) * 0x94D049BB133111EB) & mask
            return z, x ^ (x >> 31)

        def rotl(x, k):
            return ((x << k) | (x >> (64 - k))) & mask

        z, st = 0x6869_6464_656E, []
        for _ in range(4):
            z, v = splitmix(z)
            st.append(v)

        def next_u64():
            result = (rotl((st[1] * 5) & mask, 7) * 9) & mask
            t = (st[1] << 17) & mask
            st[2] ^= st[0]
            st[3] ^= st[1]
            st[1] ^= st[2]
            st[0] ^= st[3]
            st[2] ^= t
            st[3] = rotl(st[3], 45)
            return result

        def normal():
            u1 = max((next_u64() >> 11) * (1.0 / (1 << 53)), 1e-300)
            u2 = (next_u64() >> 11) * (1.0 / (1 << 53))
            return math.sqrt(-2.0 * math.log(u1)) * math.cos(2 * math.pi * u2)

        _SAMPLES = [(normal(), normal(), normal()) for _ in range(8192)]
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
    l = sorted(max(v, 0.0) for v in eigenvalues_sym3(cov))  # ascending, as the tracker
    q = sorted(l[0] * x * x + l[1] * y * y + l[2] * z * z for x, y, z in samples())
    return math.sqrt(q[math.ceil(0.95 * len(q)) - 1])


def zoom_kind(row):
    """None before any zoom, "corrected" after one the cameras followed, "uncorrected" after
    one the pose alone followed (the tracker then writes the depth change)."""
    if row["zchange"] is not None:
        return "uncorrected"
    return "corrected" if row["zsd"] > 0 else None


def constants_of(config):
    """The region's constants a run's metrics.json config names, by their short names (a
    knob missing there is one that run did not have: its value then)."""
    return {"s": config.get("covariance_scale", 1.0), "e": config.get("model_error_mm", 0.0),
            "k": config.get("model_error_per_rim_residual", 0.0),
            "r0": config.get("rim_residual_floor_mm", 0.0),
            "q": config.get("model_error_per_confidence_shortfall", 0.0),
            "c0": config.get("confidence_full", 1.0),
            "d_c": config.get("zoom_depth_sd_corrected", 0.0),
            "d_u": config.get("zoom_depth_sd_uncorrected", 0.0),
            "u": config.get("zoom_depth_per_depth_change", 0.0),
            "g": config.get("lost_growth_mm_per_frame", 0.0)}


def model_variance(row, e, k, r0, q, c0, g):
    """The per-axis variance (mm²) the constants add to a row: e² + (k · max(0, rim − ρ₀))² +
    (q · max(0, c₀ − conf))² + (g · n)², n frames into a loss."""
    return e * e + (k * max(row["rim"] - r0, 0.0)) ** 2 + (q * max(c0 - row["conf"], 0.0)) ** 2 \
        + (g * row["lost"]) ** 2


def data_part(row, config):
    """The covariance the fit's information gives (before the constants), taken back out of
    what the tracker wrote: Σ = s · data + model_variance I + zsd² c cᵀ (a lost frame keeps
    the last good frame's data part, rim, confidence and zoom terms)."""
    k = constants_of(config)
    diag = model_variance(row, k["e"], k["k"], k["r0"], k["q"], k["c0"], k["g"])
    c, z = row["c"], row["zsd"]
    return [[(row["cov"][i][j] - (diag if i == j else 0) - z * z * c[i] * c[j]) / k["s"]
             for j in range(3)] for i in range(3)]


def rebuilt(row, s, e, k, r0, d_c, d_u, u, g, q=0.0, c0=1.0):
    """A row's covariance rebuilt from its data part with the constants, as the tracker builds
    it."""
    c = row["c"]
    kind = zoom_kind(row)
    if kind == "corrected":
        z2 = d_c * d_c
    elif kind == "uncorrected":
        z2 = d_u * d_u + (u * row["zchange"]) ** 2
    else:
        z2 = 0.0
    diag = model_variance(row, e, k, r0, q, c0, g)
    return [[s * row["data"][i][j] + (diag if i == j else 0) + z2 * c[i] * c[j]
             for j in range(3)] for i in range(3)]


def inside(row, radius):
    return math.sqrt(sum(v * v for v in row["err"])) <= radius


def coverage(rows, constants):
    radii = [radius95(rebuilt(r, **constants)) for r in rows]
    cover = sum(inside(r, rad) for r, rad in zip(rows, radii)) / len(rows)
    return cover, statistics.median(radii)


def smallest(rows, grid, base):
    """The constants on `grid` (name -> values, the rest from `base`) with the smallest median
    radius whose coverage of `rows` is at least 95 %; None if none reaches it."""
    names = list(grid)
    best = None

    def walk(i, chosen):
        nonlocal best
        if i == len(names):
            constants = dict(base, **chosen)
            cover, med = coverage(rows, constants)
            if cover >= 0.95 and (best is None or med < best[1]):
                best = (constants, med, cover)
            return
        for v in grid[names[i]]:
            walk(i + 1, dict(chosen, **{names[i]: v}))

    walk(0, {})
    return best


def with_lost_growth(base, rows_by_mode):
    """`base` with the smallest lost-frame growth g on its grid that holds 95 % of the lost
    frames of every mode; returns the constants, each mode's coverage and median radius with
    them, and the number of lost frames."""
    lost = [r for rows in rows_by_mode.values() for r in rows if r["lost"]]
    for g in [0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0]:
        base = dict(base, g=g)
        if lost and coverage(lost, base)[0] >= 0.95:
            break
    return base, {m: coverage(rows, base) for m, rows in rows_by_mode.items()}, len(lost)


def calibrate(rows_by_mode, config):
    """LSC: s, e, k, d_c on its tracked frames; LS: d_u and u with those kept; then g on the
    lost frames of both. Returns the constants and what they give per mode."""
    base = constants_of(config)
    tracked = {m: [r for r in rows if not r["lost"]] for m, rows in rows_by_mode.items()}
    if "LSC" in tracked:
        found = smallest(tracked["LSC"], {
            "s": [0.25, 0.5, 1, 2, 4, 8], "e": [0.0, 0.5, 0.75, 1.0, 1.25, 1.5],
            "k": [0.0, 1.0, 2.0, 3.0], "d_c": [0.0, 0.005, 0.01, 0.015, 0.02]}, base)
        if found is None:
            return None
        base = found[0]
    if "LS" in tracked:
        found = smallest(tracked["LS"], {
            "d_u": [0.0, 0.01, 0.02, 0.03, 0.04, 0.06],
            "u": [0.0, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5]}, base)
        if found is None:
            return None
        base = found[0]
    return with_lost_growth(base, rows_by_mode)


# A 95 % region must hold about 95 % whether or not the cameras zoomed (pooled tuning frames
# of each condition, each mode): `calibrate_joint` takes nothing outside this.
BALANCED = (0.93, 0.97)
# ... and whether or not the fit was sure of its contours (its confidence under this or not).
CONFIDENT = 0.7


def kind_of_scene(spec):
    """What makes a scene's frames miss together: a KiTS patient's shape, a zoom, four views."""
    return (spec[5] is not None, spec[6], spec[4] == 4)


def set_draws(scenes, shaped_like, draws=2000, seed=16):
    """`draws` sets of tuning scenes (indices into `scenes`, the specs that have tracked rows)
    shaped like the set `shaped_like`: for each of its scenes one tuning scene of the same kind,
    none twice. A set's frames miss together scene by scene, so what a held-out set will show
    is judged on sets like it, not on the pooled frames."""
    rng = random.Random(seed)
    pools = {}
    for i, spec in enumerate(scenes):
        pools.setdefault(kind_of_scene(spec), []).append(i)
    out = []
    for _ in range(draws):
        chosen = []
        for spec in shaped_like:
            pool = [i for i in pools.get(kind_of_scene(spec), []) if i not in chosen]
            if not pool:
                return None
            chosen.append(rng.choice(pool))
        out.append(chosen)
    return out


def calibrate_joint(rows_by_mode, config, scenes):
    """Like `calibrate`, but judged as the held-out set will be: the constants on the grid
    whose 16-scene sets drawn from the tuning scenes like the test set (`set_draws`) most often
    meet the issue in both modes, coverage 90-98 % with a median radius of at most 4 mm (the
    smaller of the two modes' shares, to 0.01; ties to the smaller mean median radius). Pooled
    frames hide that a set's frames miss scene by scene: 95 % of the pooled frames with a
    region that does not widen where the fit is worse gave 89.6 % on one test set.

    Only constants whose region is calibrated whether or not the cameras zoomed, and whether
    or not the fit was confident, qualify: in each mode, the pooled tuning frames under a zoom
    and those before or without one, and those whose fit's confidence is under `CONFIDENT` and
    the others, must each hold the truth in `BALANCED` (93-97 %). Without it the sets' share was highest for a region
    too wide under a zoom and too narrow without one (224 tuning scenes, LSC: 98.6 % of the
    zoomed frames at 4.0 mm, 88.0 % of the others at 2.1 mm), a 95 % region that held 88 % in
    the commonest case.

    The grid is screened with the first 1024 of the tracker's normal samples and the best
    candidates judged again with all of them. Every frame counts, lost ones too (with the lost
    growth g as configured), as the test set counts them. `scenes`: each row's "scene" indexes
    it. Needs numpy; None when no set meets it."""
    import numpy as np
    every_z2 = np.array(samples()) ** 2
    used = sorted({r["scene"] for rows in rows_by_mode.values() for r in rows})
    draws = set_draws([scenes[i] for i in used], TEST)
    if draws is None:
        print("  warning: a kind of test scene has too few tuning scenes to draw sets like the "
              "test set; falling back to the staged search on pooled frames (rim floor and "
              "confidence terms as configured, no balance)")
        return calibrate(rows_by_mode, config)
    draws = np.array(draws)
    column = {scene: i for i, scene in enumerate(used)}

    def prepared(rows):
        kinds = [zoom_kind(r) for r in rows]
        scene = np.array([column[r["scene"]] for r in rows])
        slot = np.zeros(len(rows), dtype=int)
        seen = {}
        for i, sc in enumerate(scene):
            slot[i] = seen.get(sc, 0)
            seen[sc] = slot[i] + 1
        return {
            "data": np.array([r["data"] for r in rows]),
            "rim": np.array([r["rim"] for r in rows]),
            "conf": np.array([r["conf"] for r in rows]),
            "cc": np.array([np.outer(r["c"], r["c"]) for r in rows]),
            "corrected": np.array([k == "corrected" for k in kinds], dtype=float),
            "uncorrected": np.array([k == "uncorrected" for k in kinds], dtype=float),
            "zoomed": np.array([k is not None for k in kinds]),
            "zchange2": np.array([(r["zchange"] or 0.0) ** 2 for r in rows]),
            "err": np.array([math.sqrt(sum(v * v for v in r["err"])) for r in rows]),
            "lost2": np.array([float(r["lost"]) ** 2 for r in rows]),
            "scene": scene, "slot": slot, "width": int(slot.max()) + 1,
        }

    g = config.get("lost_growth_mm_per_frame", 0.0)

    def evaluate(p, z2, s, e, k, r0, q, c0, d_c, d_u, u):
        """(share of sets meeting the issue, median radius) or None when unbalanced."""
        k95 = math.ceil(0.95 * len(z2)) - 1
        # Lost frames count as the test set counts them, with the lost growth g kept.
        diag = e * e + (k * np.maximum(p["rim"] - r0, 0.0)) ** 2 \
            + (q * np.maximum(c0 - p["conf"], 0.0)) ** 2 + g * g * p["lost2"]
        z = p["corrected"] * d_c * d_c + p["uncorrected"] * (d_u * d_u + u * u * p["zchange2"])
        cov = s * p["data"] + diag[:, None, None] * np.eye(3) + z[:, None, None] * p["cc"]
        lam = np.maximum(np.linalg.eigvalsh(cov), 0.0)
        radii = np.sqrt(np.partition(lam @ z2.T, k95, axis=1)[:, k95])
        inside = p["err"] <= radii
        unsure = p["conf"] < CONFIDENT
        for part in (p["zoomed"], ~p["zoomed"], unsure, ~unsure):
            if part.any() and not BALANCED[0] <= inside[part].mean() <= BALANCED[1]:
                return None
        n = len(used)
        held = np.bincount(p["scene"], inside, minlength=n)
        count = np.bincount(p["scene"], minlength=n)
        by_scene = np.full((n, p["width"]), np.nan)
        by_scene[p["scene"], p["slot"]] = radii
        cover = held[draws].sum(1) / np.maximum(count[draws].sum(1), 1)
        median = np.nanmedian(by_scene[draws].reshape(len(draws), -1), axis=1)
        met = float(np.mean((cover >= 0.90) & (cover <= 0.98) & (median <= 4.0)))
        return round(met, 2), float(np.median(radii))

    every = {m: prepared(rows) for m, rows in rows_by_mode.items() if rows}
    if set(every) != {"LSC", "LS"}:
        return calibrate(rows_by_mode, config)

    def best_of(mode, z2, base, options):
        scored = [(evaluate(every[mode], z2, *base, *o), o) for o in options]
        scored = [(j, o) for j, o in scored if j is not None]
        return max(scored, key=lambda x: (x[0][0], -x[0][1])) if scored else None

    # LSC candidates carry no uncorrected-zoom term: LSC corrects every zoom it meets (its
    # tuning frames have none the pose alone followed).
    lsc_options = [(d_c, 0.0, 0.0) for d_c in [0.0025, 0.005, 0.0075, 0.01, 0.0125, 0.015]]
    ls_options = [(0.0, d_u, u) for d_u in [0.0, 0.01, 0.02]
                  for u in [0.5, 0.75, 1.0, 1.25, 1.5, 2.0, 2.5]]

    def judged(z2, base, lsc_opts, ls_opts):
        lsc = best_of("LSC", z2, base, lsc_opts)
        ls = best_of("LS", z2, base, ls_opts)
        if lsc is None or ls is None:
            return None
        score = (min(lsc[0][0], ls[0][0]), -0.5 * (lsc[0][1] + ls[0][1]))
        return score, base, lsc, ls

    screened = []
    for s in [1, 2, 4]:
        for e in [0.5, 0.625, 0.75, 0.875, 1.0]:
            for k in [0.0, 2.0, 4.0]:
                for r0 in ([0.0] if k == 0 else [0.5, 0.6]):
                    for q in [0.0, 2.0, 4.0, 6.0, 8.0]:
                        for c0 in ([1.0] if q == 0 else [0.7, 0.8, 0.9]):
                            found = judged(every_z2[:1024], (s, e, k, r0, q, c0), lsc_options,
                                           ls_options)
                            if found is not None:
                                screened.append(found)
    screened.sort(key=lambda x: x[0], reverse=True)
    best = None
    for _, base, _, _ in screened[:12]:
        found = judged(every_z2, base, lsc_options, ls_options)
        if found is not None and (best is None or found[0] > best[0]):
            best = found
    if best is None or best[0][0] <= 0.0:
        return None
    (score, (s, e, k, r0, q, c0), lsc, ls) = best
    print(f"  sets like the test set meeting the issue: LSC {100 * lsc[0][0]:.0f} %, "
          f"LS {100 * ls[0][0]:.0f} % of {len(draws)}")
    return with_lost_growth({"s": s, "e": e, "k": k, "r0": r0, "q": q, "c0": c0,
                             "d_c": lsc[1][0], "d_u": ls[1][1], "u": ls[1][2], "g": g},
                            rows_by_mode)


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
        rows_by_mode, config = {}, {}
        for mode in modes:
            rows = []
            for spec in sets[name]:
                r, _, config = track(make_scene(spec, work), mode, work, spec[0])
                for row in r:
                    row["scene"] = sets[name].index(spec)
                rows.extend(r)
            rows_by_mode[mode] = rows
            if not rows:
                print(f"| {name} | {mode} | 0 | – | – | – | – |")
                continue
            cover = sum(inside(r, r["radius"]) for r in rows) / len(rows)
            errs = [math.sqrt(sum(v * v for v in r["err"])) for r in rows]
            print(f"| {name} | {mode} | {len(rows)} | {100 * cover:.1f} % | "
                  f"{statistics.median(r['radius'] for r in rows):.2f} | "
                  f"{statistics.mean(errs):.2f} | {max(errs):.2f} |", flush=True)
        if args.calibrate and name == "tuning":
            try:
                import numpy  # noqa: F401
                search = calibrate_joint
            except ImportError:
                search = calibrate
            chosen_rows = {m: r for m, r in rows_by_mode.items() if r}
            found = (calibrate_joint(chosen_rows, config, sets[name])
                     if search is calibrate_joint else calibrate(chosen_rows, config))
            if found is None:
                print("  calibration: nothing on the grid qualifies (sets: none meets 90-98 % "
                      "at <= 4 mm; staged search: nothing reaches 95 %)")
                continue
            constants, per_mode, n_lost = found
            print("  calibrated: covariance_scale {s}, model_error_mm {e}, "
                  "model_error_per_rim_residual {k}, rim_residual_floor_mm {r0}, "
                  "model_error_per_confidence_shortfall {q}, confidence_full {c0}, "
                  "zoom_depth_sd_corrected {d_c}, "
                  "zoom_depth_sd_uncorrected {d_u}, zoom_depth_per_depth_change {u}, "
                  "lost_growth_mm_per_frame {g}".format(**constants) + f" ({n_lost} lost frames)")
            for m, (cover, med) in per_mode.items():
                print(f"  with them, tuning {m}: coverage {100 * cover:.1f} %, median radius "
                      f"{med:.2f} mm", flush=True)
    if not args.keep:
        print(f"(scenes and results in {work})")


if __name__ == "__main__":
    main()
