//! Whether this CPU has the instruction sets the binary was compiled to use. The default build
//! targets the CPU that builds it (`.cargo/config.toml`: `-C target-cpu=native`), so a binary
//! copied to an older or other CPU would otherwise die on its first such instruction with a bare
//! "Illegal instruction". `main` asks first and says what is missing and how to rebuild.
//! Best effort: the check runs before any of the fit's code, but the compiler may use the
//! instructions anywhere, so a CPU lacking them can still fail before it.

/// One list of names gives both [`COMPILED`] and [`detected`]: `is_x86_feature_detected!`
/// takes only literals, and two lists kept apart could drift.
#[cfg(target_arch = "x86_64")]
macro_rules! features {
    ($($name:tt),* $(,)?) => {
        /// The x86-64 features beyond the baseline (SSE2) that the compiler may use on its
        /// own, with whether this binary was compiled with each.
        const COMPILED: &[(&str, bool)] = &[$(($name, cfg!(target_feature = $name))),*];

        /// Whether the running CPU has `feature`; `None` for a name not among [`COMPILED`]'s.
        fn detected(feature: &str) -> Option<bool> {
            Some(match feature {
                $($name => is_x86_feature_detected!($name),)*
                _ => return None,
            })
        }
    };
}

#[cfg(target_arch = "x86_64")]
features!(
    "sse3", "ssse3", "sse4.1", "sse4.2", "popcnt", "avx", "avx2", "fma", "bmi1", "bmi2", "lzcnt",
    "f16c", "movbe", "avx512f", "avx512bw", "avx512cd", "avx512dq", "avx512vl",
);

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
