//! Whether this CPU has the instruction sets the binary was compiled to use. The default build
//! targets the CPU that builds it (`.cargo/config.toml`: `-C target-cpu=native`), so a binary
//! copied to an older or other CPU would otherwise die on its first such instruction with a bare
//! "Illegal instruction". `main` asks first and says what is missing and how to rebuild.
//! Best effort: the check runs before any of the fit's code, but the compiler may use the
//! instructions anywhere, so a CPU lacking them can still fail before it.

/// The x86-64 features beyond the baseline (SSE2) that the compiler may use on its own, with
/// whether this binary was compiled with each.
#[cfg(target_arch = "x86_64")]
const COMPILED: &[(&str, bool)] = &[
    ("sse3", cfg!(target_feature = "sse3")),
    ("ssse3", cfg!(target_feature = "ssse3")),
    ("sse4.1", cfg!(target_feature = "sse4.1")),
    ("sse4.2", cfg!(target_feature = "sse4.2")),
    ("popcnt", cfg!(target_feature = "popcnt")),
    ("avx", cfg!(target_feature = "avx")),
    ("avx2", cfg!(target_feature = "avx2")),
    ("fma", cfg!(target_feature = "fma")),
    ("bmi1", cfg!(target_feature = "bmi1")),
    ("bmi2", cfg!(target_feature = "bmi2")),
    ("lzcnt", cfg!(target_feature = "lzcnt")),
    ("f16c", cfg!(target_feature = "f16c")),
    ("movbe", cfg!(target_feature = "movbe")),
    ("avx512f", cfg!(target_feature = "avx512f")),
    ("avx512bw", cfg!(target_feature = "avx512bw")),
    ("avx512cd", cfg!(target_feature = "avx512cd")),
    ("avx512dq", cfg!(target_feature = "avx512dq")),
    ("avx512vl", cfg!(target_feature = "avx512vl")),
];

/// Whether the running CPU has `feature`; `None` for a name not among [`COMPILED`]'s.
#[cfg(target_arch = "x86_64")]
fn detected(feature: &str) -> Option<bool> {
    Some(match feature {
        "sse3" => is_x86_feature_detected!("sse3"),
        "ssse3" => is_x86_feature_detected!("ssse3"),
        "sse4.1" => is_x86_feature_detected!("sse4.1"),
        "sse4.2" => is_x86_feature_detected!("sse4.2"),
        "popcnt" => is_x86_feature_detected!("popcnt"),
        "avx" => is_x86_feature_detected!("avx"),
        "avx2" => is_x86_feature_detected!("avx2"),
        "fma" => is_x86_feature_detected!("fma"),
        "bmi1" => is_x86_feature_detected!("bmi1"),
        "bmi2" => is_x86_feature_detected!("bmi2"),
        "lzcnt" => is_x86_feature_detected!("lzcnt"),
        "f16c" => is_x86_feature_detected!("f16c"),
        "movbe" => is_x86_feature_detected!("movbe"),
        "avx512f" => is_x86_feature_detected!("avx512f"),
        "avx512bw" => is_x86_feature_detected!("avx512bw"),
        "avx512cd" => is_x86_feature_detected!("avx512cd"),
        "avx512dq" => is_x86_feature_detected!("avx512dq"),
        "avx512vl" => is_x86_feature_detected!("avx512vl"),
        _ => return None,
    })
}

/// The compiled-in features that `has` says the CPU lacks.
#[cfg(target_arch = "x86_64")]
fn missing_with(has: impl Fn(&str) -> bool) -> Vec<&'static str> {
    COMPILED
        .iter()
        .filter(|(name, compiled)| *compiled && !has(name))
        .map(|(name, _)| *name)
        .collect()
}

/// The instruction sets this binary was compiled to use and this CPU lacks (none elsewhere
/// than x86-64).
pub fn missing_features() -> Vec<&'static str> {
    #[cfg(target_arch = "x86_64")]
    {
        missing_with(|name| detected(name).unwrap_or(false))
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        Vec::new()
    }
}

/// What to tell a user whose CPU lacks `missing`.
pub fn mismatch_message(missing: &[&str]) -> String {
    format!(
        "this endofuse binary was built for another CPU: this one lacks {} (the default build \
         targets the CPU that builds it). Build it on this machine (`cargo build --release`), \
         or build one for any x86-64 CPU of the last 15 years with \
         RUSTFLAGS=\"-C target-cpu=x86-64-v2\" cargo build --release",
        missing.join(", ")
    )
}

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    use super::*;

    /// The machine that builds and tests the binary has every feature it was compiled with
    /// (the default build targets it), and a CPU that has none of them is told each one the
    /// build uses: SSE2-only x86-64 lacks all that `COMPILED` lists.
    #[test]
    fn the_building_cpu_has_what_was_compiled_in_and_a_bare_one_lacks_it() {
        assert_eq!(missing_features(), Vec::<&str>::new());
        let compiled: Vec<&str> = COMPILED
            .iter()
            .filter(|(_, on)| *on)
            .map(|(name, _)| *name)
            .collect();
        assert_eq!(missing_with(|_| false), compiled);
        // Every listed name is one the run-time detection knows (an unknown one would read
        // as missing on every CPU), and a CPU reporting all of them lacks nothing.
        for (name, _) in COMPILED {
            assert!(detected(name).is_some(), "{name} unknown to detection");
        }
        assert!(missing_with(|_| true).is_empty());
        let message = mismatch_message(&["avx2", "fma"]);
        assert!(message.contains("lacks avx2, fma"), "{message}");
        assert!(message.contains("target-cpu=x86-64-v2"), "{message}");
    }
}
