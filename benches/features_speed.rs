//! Benchmark: what the appearance features cost (issue 13: "measure ms per 1080p frame";
//! issue 14: the fit's per-frame feature preparation). On a phantom frame at 960×540 and
//! 1920×1080, one thread and all threads:
//!
//!     cargo bench --bench features_speed
//!
//! - prepare: per-pixel channels (CIELAB, normalised rg) and the summed-area tables of a whole
//!   frame — what every classification of a frame starts with;
//! - all: every pixel's 72 features after that (the full probability map's input);
//! - fit region: the fit's preparation of one view at pyramid level 1 (a 420×270 region, as
//!   `track` builds for a kidney filling a 960×540 view), then 5,000 scattered pixels'
//!   vectors from it (the correspondence lines' samples), in row-major order as
//!   `ViewProbabilities::ensure` asks for them (before 2026-12-05 in random order, ~15 %
//!   slower).
//!
//! Median of seven runs. Not part of CI.

use endofuse::appearance::FrameFeatures;
use endofuse::appearance::features::downsample;
use endofuse::synth::{SynthOptions, memory_scene};
use std::time::Instant;

fn median_ms(mut f: impl FnMut()) -> f64 {
    let mut t: Vec<f64> = (0..7)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[3]
}

fn measure(width: u32, height: u32) {
    let scene = memory_scene(&SynthOptions {
        frames: 1,
        seed: 41,
        width,
        height,
        vary_look: true,
        tools: true,
        ..SynthOptions::default()
    })
    .expect("phantom");
    let frame = scene.frame(0, 0).expect("frame");
    let prepare = median_ms(|| {
        std::hint::black_box(FrameFeatures::new(&frame));
    });
    let ff = FrameFeatures::new(&frame);
    let all = median_ms(|| {
        std::hint::black_box(ff.all());
    });
    let half = downsample(&frame);
    let (rw, rh) = (
        (half.width() as usize * 7 / 8).max(1),
        half.height() as usize,
    );
    let region = median_ms(|| {
        std::hint::black_box(FrameFeatures::region(&half, 1, 0, 0, rw, rh));
    });
    let fr = FrameFeatures::region(&half, 1, 0, 0, rw, rh);
    // Scattered pixels, as the lines' samples are: a fixed pseudo-random walk.
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let pixels: Vec<(u32, u32)> = (0..5000)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (
                (state % rw as u64) as u32,
                ((state >> 32) % rh as u64) as u32,
            )
        })
        .collect();
    let mut pixels = pixels;
    pixels.sort_by_key(|&(x, y)| (y, x));
    let sparse = median_ms(|| {
        std::hint::black_box(fr.pixels(&pixels));
    });
    println!(
        "{width}×{height}, {} threads: prepare {prepare:.1} ms, all {all:.1} ms (a whole frame's \
         features {:.1} ms); fit region {rw}×{rh} at level 1: prepare {region:.2} ms, 5,000 \
         pixels {sparse:.2} ms",
        rayon::current_num_threads(),
        prepare + all
    );
}

fn main() {
    for (w, h) in [(960, 540), (1920, 1080)] {
        measure(w, h);
        rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .expect("pool")
            .install(|| measure(w, h));
    }
}
