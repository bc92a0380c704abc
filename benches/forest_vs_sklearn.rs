//! Benchmark: our forest against scikit-learn's RandomForestClassifier (20 trees, n_jobs=2) on
//! the same exported features and samples, in one run.
//!
//!     cargo bench --bench forest_vs_sklearn
//!     BENCH_THREADS=1 cargo bench --bench forest_vs_sklearn   # one core each
//!
//! Trains on the seed strokes of frames 0–2 of a 960×540 stereo phantom (tools, noise 0.03),
//! tests on every pixel of frames 5 and 9 in both views against ground truth. The Python half
//! (`benches/sklearn_forest.py`) pip-installs scikit-learn if it is missing. Not part of CI.
//!
//! Inference takes the masks (`appearance::forest::masks`) where the CPU has AVX-512BW or AVX2,
//! else the lockstep walk; `ENDOFUSE_FOREST_WALK=1` forces the walk, `ENDOFUSE_FOREST_AVX2=1`
//! the AVX2 masks. `FOREST_SHUFFLE=1` puts the test
//! pixels in random order (neighbours no longer share paths); `FOREST_LABEL_NOISE=0.05` draws
//! that share of the training labels at random (large, deep trees, as hard tissue grows);
//! `FOREST_PROFILE=1` adds one-thread timings of forests of 1, 5 and 20 trees.
//!
//! Accuracy is also compared over `FOREST_SEEDS` (5 unless given) forests per side, one per
//! random seed: a single forest's accuracy moves with its seed by about as much as the two
//! forests differ, so one pair of forests cannot say which is ahead.

use endofuse::appearance::forest::argmax;
use endofuse::appearance::{
    ClassMap, FEATURE_COUNT, Forest, ForestParams, FrameFeatures, Samples, collect_samples,
};
use endofuse::synth::{SynthOptions, memory_scene};
use std::io::Write;
use std::path::Path;
use std::time::Instant;

fn write(path: &Path, bytes: &[u8]) {
    std::fs::File::create(path)
        .and_then(|mut f| f.write_all(bytes))
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
}

fn main() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/forest-bench");
    std::fs::create_dir_all(&dir).unwrap();
    eprintln!("making the phantom (960×540, 10 frames, tools, noise 0.03)…");
    let scene = memory_scene(&SynthOptions {
        frames: 10,
        seed: 5,
        noise: 0.03,
        ..SynthOptions::default()
    })
    .unwrap();
    let classes = ClassMap::from_scene(&scene);
    let started = Instant::now();
    let train = collect_samples(&scene, &classes, None).unwrap();
    let extract_train_s = started.elapsed().as_secs_f64();
    // FOREST_LABEL_NOISE=0.1: that share of the training labels drawn at random, for the large,
    // deep trees that hard (real) tissue grows.
    let mut train = train;
    if let Some(share) = std::env::var("FOREST_LABEL_NOISE")
        .ok()
        .and_then(|v| v.parse::<f64>().ok())
    {
        let mut rng = endofuse::rng::Rng::new(12);
        for c in train.classes.iter_mut() {
            if rng.uniform() < share {
                *c = rng.below(classes.len()) as u8;
            }
        }
    }
    let mut test = Samples::default();
    let mut extract_ms = Vec::new();
    for t in [5usize, 9] {
        for c in 0..scene.cameras.len() {
            let frame = scene.frame(c, t).unwrap();
            let s = Instant::now();
            let ff = FrameFeatures::new(&frame);
            let all = ff.all();
            extract_ms.push(s.elapsed().as_secs_f64() * 1e3);
            let gt = scene.ground_truth_labels(c, t).unwrap().unwrap();
            for (f, &l) in all.into_iter().zip(&gt.data) {
                test.push(f, classes.class_of_label(l).unwrap_or(0) as u8);
            }
        }
    }
    // FOREST_SHUFFLE=1: test pixels in a random order, not image order (neighbours no longer
    // share their paths through the trees, as in sparse classification).
    if std::env::var_os("FOREST_SHUFFLE").is_some() {
        let mut rng = endofuse::rng::Rng::new(11);
        for i in (1..test.len()).rev() {
            let j = rng.below(i + 1);
            test.features.swap(i, j);
            test.classes.swap(i, j);
        }
    }
    let flat = |s: &Samples| {
        s.features
            .iter()
            .flat_map(|f| f.iter().copied())
            .collect::<Vec<u8>>()
    };
    write(&dir.join("train_x.u8"), &flat(&train));
    write(&dir.join("train_y.u8"), &train.classes);
    write(&dir.join("test_x.u8"), &flat(&test));
    write(&dir.join("test_y.u8"), &test.classes);
    write(
        &dir.join("meta.json"),
        format!(
            "{{\"features\": {FEATURE_COUNT}, \"classes\": {}}}",
            classes.len()
        )
        .as_bytes(),
    );

    let mut params = ForestParams::default();
    if let Some(d) = std::env::var("FOREST_DEPTH")
        .ok()
        .and_then(|v| v.parse().ok())
    {
        params.max_depth = d;
    }
    if let Some(d) = std::env::var("FOREST_LEAF")
        .ok()
        .and_then(|v| v.parse().ok())
    {
        params.min_samples_leaf = d;
    }
    if let Some(d) = std::env::var("FOREST_SAMPLES")
        .ok()
        .and_then(|v| v.parse().ok())
    {
        params.max_samples_per_tree = d;
    }
    // BENCH_THREADS=1 compares one core against one core (both sides), e.g. while the other
    // core is busy; the default is both cores on both sides.
    let threads: usize = std::env::var("BENCH_THREADS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(2);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let s = Instant::now();
    let (forest, stats) = pool.install(|| Forest::train(&train, classes.len(), &params).unwrap());
    let ours_train_s = s.elapsed().as_secs_f64();
    // Best of three for inference.
    let mut ours_predict_s = f64::INFINITY;
    let mut probs = Vec::new();
    for _ in 0..3 {
        let s = Instant::now();
        probs = pool.install(|| forest.predict_many(&test.features));
        ours_predict_s = ours_predict_s.min(s.elapsed().as_secs_f64());
    }
    let k = classes.len();
    // Share of test pixels whose most probable class is the true one.
    let accuracy = |probs: &[f32]| {
        (0..test.len())
            .filter(|&i| argmax(&probs[i * k..(i + 1) * k]) == test.classes[i] as usize)
            .count() as f64
            / test.len() as f64
    };
    let ours_acc = accuracy(&probs);
    let ours_rate = test.len() as f64 / ours_predict_s;
    let seeds: usize = std::env::var("FOREST_SEEDS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(5);
    let mut ours_seed_acc = vec![ours_acc];
    for i in 1..seeds as u64 {
        let p = ForestParams {
            seed: params.seed.wrapping_add(i),
            ..params.clone()
        };
        let (f, _) = pool.install(|| Forest::train(&train, classes.len(), &p).unwrap());
        ours_seed_acc.push(accuracy(&pool.install(|| f.predict_many(&test.features))));
    }

    eprintln!("running scikit-learn on the same data…");
    let py = std::process::Command::new("python3")
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/sklearn_forest.py"))
        .arg(&dir)
        .arg(threads.to_string())
        .arg(seeds.to_string())
        .output();
    let sk: Option<serde_json::Value> = match py {
        Ok(out) if out.status.success() => String::from_utf8_lossy(&out.stdout)
            .lines()
            .last()
            .and_then(|l| serde_json::from_str(l).ok()),
        Ok(out) => {
            eprintln!(
                "scikit-learn run failed: {}",
                String::from_utf8_lossy(&out.stderr)
            );
            None
        }
        Err(e) => {
            eprintln!("cannot run python3: {e}");
            None
        }
    };
    eprintln!("tree depths: {:?}", forest.depths());
    if std::env::var_os("FOREST_PROFILE").is_some() {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        for trees in [1usize, 5, 20] {
            let (f, _) = Forest::train(
                &train,
                classes.len(),
                &ForestParams {
                    trees,
                    ..params.clone()
                },
            )
            .unwrap();
            let s = Instant::now();
            pool.install(|| f.predict_many(&test.features));
            let ns = s.elapsed().as_secs_f64() * 1e9 / test.len() as f64;
            eprintln!(
                "1 thread, {trees} trees: {ns:.1} ns per pixel ({:.1} per tree)",
                ns / trees as f64
            );
        }
    }
    let mean_extract = extract_ms.iter().sum::<f64>() / extract_ms.len() as f64;
    println!("threads: {threads} (ours) and n_jobs={threads} (scikit-learn)");
    println!(
        "training samples: {} (features of 6 seeded views: {:.2} s); test pixels: {}",
        train.len(),
        extract_train_s,
        test.len()
    );
    println!("feature extraction, full 960×540 view: {mean_extract:.1} ms");
    println!(
        "{:<14} {:>10} {:>16} {:>10}",
        "forest", "train s", "predict px/s", "accuracy"
    );
    println!(
        "{:<14} {:>10.3} {:>16.0} {:>10.4}   (OOB error {:.4}, {} nodes)",
        "endofuse", ours_train_s, ours_rate, ours_acc, stats.oob_error, stats.nodes
    );
    if let Some(sk) = sk {
        let (tr, rate, acc) = (
            sk["train_s"].as_f64().unwrap_or(f64::NAN),
            sk["predict_px_per_s"].as_f64().unwrap_or(f64::NAN),
            sk["accuracy"].as_f64().unwrap_or(f64::NAN),
        );
        println!(
            "{:<14} {:>10.3} {:>16.0} {:>10.4}   ({})",
            "scikit-learn",
            tr,
            rate,
            acc,
            sk["version"].as_str().unwrap_or("?")
        );
        println!(
            "ratios: training {:.1}× faster, inference {:.1}× the throughput, accuracy {:+.4}",
            tr / ours_train_s,
            ours_rate / rate,
            ours_acc - acc
        );
        let sk_seed_acc: Vec<f64> = sk["seed_accuracies"]
            .as_array()
            .map(|a| a.iter().filter_map(|v| v.as_f64()).collect())
            .unwrap_or_default();
        let summary = |a: &[f64]| {
            let mean = a.iter().sum::<f64>() / a.len().max(1) as f64;
            let lo = a.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = a.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            (mean, lo, hi)
        };
        let (om, olo, ohi) = summary(&ours_seed_acc);
        let (sm, slo, shi) = summary(&sk_seed_acc);
        println!(
            "accuracy over {} forest seeds each: endofuse {om:.4} ({olo:.4}–{ohi:.4}), \
             scikit-learn {sm:.4} ({slo:.4}–{shi:.4}), difference of the means {:+.5}",
            ours_seed_acc.len().min(sk_seed_acc.len().max(1)),
            om - sm
        );
    }
}
