//! Benchmark: the app's live loop at 960×540 (issue 13: retrain + repaint of the visible frame
//! in ≤ 300 ms). Times what the app waits for after a stroke ends, on a phantom with the
//! synth's strokes on three frames of two views, as the worker does it:
//!
//!     cargo bench --bench live_update
//!
//! A stroke changes one image's seeds: the retrain reads that image again (the others' samples
//! are cached), trains the forest, and the visible frame's two views are classified, a coarse
//! map first (level 1, drawn while the full one is made), then the full map; the held-out
//! figure comes last. Median of five runs per stage. Not part of CI.

use endofuse::appearance::{Appearance, ForestParams, SampleCache, TrainingSet};
use endofuse::scene::SEED_BACKGROUND;
use endofuse::synth::{SynthOptions, memory_scene};
use std::time::Instant;

fn median_ms(mut f: impl FnMut()) -> f64 {
    let mut t: Vec<f64> = (0..5)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[2]
}

fn main() {
    let scene = memory_scene(&SynthOptions {
        frames: 4,
        seed: 40,
        vary_look: true,
        ..SynthOptions::default()
    })
    .expect("phantom");
    let mut params = ForestParams::default();
    // LIVE_FOREST_SAMPLES caps each tree's draws, to explore.
    if let Some(n) = std::env::var("LIVE_FOREST_SAMPLES")
        .ok()
        .and_then(|v| v.parse().ok())
    {
        params.max_samples_per_tree = n;
    }
    let cache = SampleCache::default();
    let first = TrainingSet::collect(&scene, None, Some(&cache)).expect("seeds");
    // One more stroke on frame 0 of the left view: a short background line.
    let mut stroke = 0u8;
    let mut stroked = || {
        stroke = stroke.wrapping_add(1);
        let mut seeds = scene.seeds.clone();
        let s = seeds.by_camera[0].get_mut(&0).expect("seeded frame 0");
        let y = 10 + stroke as usize % 20;
        for x in 10..60 {
            let i = y * s.width + x;
            s.data[i] = SEED_BACKGROUND;
        }
        scene.with_seeds(seeds)
    };
    let cold = median_ms(|| {
        std::hint::black_box(TrainingSet::collect(&scene, None, None).expect("seeds"));
    });
    let mut set = None;
    let collect = median_ms(|| {
        let s = stroked();
        set = Some(TrainingSet::collect(&s, None, Some(&cache)).expect("seeds"));
    });
    let set = set.expect("collected");
    let mut appearance = None;
    let forest = median_ms(|| appearance = Some(Appearance::fit(&set, &params).expect("forest")));
    let appearance = appearance.expect("trained");
    let validate = median_ms(|| {
        std::hint::black_box(set.validate(&params));
    });
    let frames: Vec<_> = (0..2).map(|c| scene.frame(c, 3).expect("frame")).collect();
    let coarse = median_ms(|| {
        for f in &frames {
            std::hint::black_box(appearance.classify_coarse(f));
        }
    });
    let full = median_ms(|| {
        for f in &frames {
            std::hint::black_box(appearance.classify_frame(f));
        }
    });
    println!(
        "live update at {}×{}, 2 views, {} seeded pixels ({} before the stroke), {} trees:",
        frames[0].width(),
        frames[0].height(),
        set.samples.len(),
        first.samples.len(),
        params.trees
    );
    println!(
        "  seeds' features: {collect:.0} ms (the stroked image only; all images {cold:.0} ms)"
    );
    println!("  forest: {forest:.0} ms");
    println!("  coarse maps of the visible frame: {coarse:.0} ms; full maps: {full:.0} ms");
    println!("  held-out figure (after the maps): {validate:.0} ms");
    println!(
        "  stroke end -> coarse maps shown: {:.0} ms (+50 ms the app waits for a next stroke); -> full maps: {:.0} ms",
        collect + forest + coarse,
        collect + forest + coarse + full
    );
}
