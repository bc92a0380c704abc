//! Recycled buffers for the per-frame fit. Every tracked frame builds feature tables and
//! probability planes of megabytes; fresh allocations of that size cost page faults and
//! zeroing on every frame, recycled ones do not. A pool keeps a bounded number of buffers and
//! hands out any that is large enough.

use std::sync::Mutex;

/// Bytes a pool keeps at most: two views' feature tables and probability planes at 960×540
/// take about 14 MB; training on whole 1080p frames would otherwise park hundreds.
const KEEP_BYTES: usize = 64 << 20;

pub struct Pool<T> {
    free: Mutex<Vec<Vec<T>>>,
}

impl<T: Copy> Pool<T> {
    pub const fn new() -> Self {
        Self {
            free: Mutex::new(Vec::new()),
        }
    }

    /// A buffer of `len` entries. Entries a recycled buffer already had keep whatever they
    /// held; the caller clears what it reads before writing. Entries beyond are `fill`.
    pub fn take(&self, len: usize, fill: T) -> Vec<T> {
        let found = self.free.lock().ok().and_then(|mut free| {
            let i = free.iter().position(|b| b.capacity() >= len)?;
            Some(free.swap_remove(i))
        });
        let mut buf = found.unwrap_or_default();
        buf.truncate(len);
        buf.resize(len, fill);
        buf
    }

    /// Hands buffers back (dropped when the pool is full).
    pub fn give(&self, buffers: impl IntoIterator<Item = Vec<T>>) {
        let bytes = |b: &Vec<T>| b.capacity() * std::mem::size_of::<T>();
        if let Ok(mut free) = self.free.lock() {
            let mut kept: usize = free.iter().map(bytes).sum();
            for b in buffers {
                if b.capacity() > 0 && kept + bytes(&b) <= KEEP_BYTES {
                    kept += bytes(&b);
                    free.push(b);
                }
            }
        }
    }
}

impl<T: Copy> Default for Pool<T> {
    fn default() -> Self {
        Self::new()
    }
}

/// Runs `f` on a thread of rayon's global pool, the caller waiting; on a pool thread already,
/// runs it in place. Work that alternates serial stretches with many short parallel loops (a
/// frame's fit: a few dozen loops of 0.1–1 ms) is faster there: a loop started from outside
/// the pool hands its work over and sleeps until the pool's threads wake, work and wake it
/// again, where a pool thread starts on the work at once and the other joins it. On the
/// 2-core machine, 200 rounds of 300 µs serial work and a loop of 160 µs of work: 572–587 µs
/// per round from outside, 406–432 µs from inside (ideal 380).
pub fn on_workers<T: Send>(f: impl FnOnce() -> T + Send) -> T {
    if rayon::current_thread_index().is_some() {
        return f();
    }
    // From outside the pool, `join` runs its first closure on a pool thread.
    rayon::join(f, || ()).0
}

thread_local! {
    /// Set while [`serially`] runs on this thread: the loops that ask [`min_split`] then run
    /// whole on it.
    static SERIAL: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Runs `f` with the parallel loops that ask [`min_split`] kept whole on this thread. For
/// coarse work split by hand (one view per core): inside it, a thread waiting on its own
/// nested loop would steal the other view whole, and the two would run one after the other.
pub fn serially<T>(f: impl FnOnce() -> T) -> T {
    /// Puts the thread's setting back however `f` ends, a panic included: a pool thread
    /// outlives the work, and left set it would run every later loop alone.
    struct Restore(bool);
    impl Drop for Restore {
        fn drop(&mut self) {
            SERIAL.with(|s| s.set(self.0));
        }
    }
    let _restore = Restore(SERIAL.with(|s| s.replace(true)));
    f()
}

/// The least number of items a parallel loop of `items` may split into pieces of
/// (`with_min_len`): all of them inside [`serially`], else `at_least`.
pub fn min_split(items: usize, at_least: usize) -> usize {
    if SERIAL.with(|s| s.get()) {
        items.max(1)
    } else {
        at_least.max(1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn buffers_come_back_with_the_asked_length() {
        let pool: Pool<u32> = Pool::new();
        let mut a = pool.take(10, 7);
        assert_eq!(a, vec![7; 10]);
        a.iter_mut().for_each(|v| *v = 1);
        pool.give([a]);
        // Shorter: a recycled buffer, cut to length, old contents kept.
        let b = pool.take(4, 0);
        assert_eq!(b, vec![1; 4]);
        pool.give([b]);
        // Longer than any kept: fresh, filled.
        let c = pool.take(20, 3);
        assert_eq!(c.len(), 20);
        assert!(c.iter().all(|&v| v == 3 || v == 1));
    }

    /// The work runs on a thread of the pool (where its parallel loops start at once), and
    /// in place when already there.
    #[test]
    fn work_runs_on_a_pool_thread() {
        assert!(rayon::current_thread_index().is_none());
        let (on_pool, nested) = super::on_workers(|| {
            let outer = rayon::current_thread_index();
            let inner = super::on_workers(rayon::current_thread_index);
            (outer.is_some(), outer == inner)
        });
        assert!(on_pool && nested);
    }

    /// Inside `serially` a loop that asks `min_split` runs whole on the calling thread, on a
    /// pool of two threads too; outside it, and after it, the loop may split again.
    #[test]
    fn serially_keeps_a_loop_on_its_thread() {
        use rayon::prelude::*;
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        let threads_of_loop = || {
            let ids: Vec<std::thread::ThreadId> = (0..4096)
                .into_par_iter()
                .with_min_len(super::min_split(4096, 1))
                .map(|_| std::thread::current().id())
                .collect();
            (
                ids.iter().all(|&t| t == std::thread::current().id()),
                ids.len(),
            )
        };
        pool.install(|| {
            assert_eq!(super::serially(threads_of_loop), (true, 4096));
            assert_eq!(super::min_split(4096, 16), 16);
            assert_eq!(super::serially(|| super::min_split(4096, 16)), 4096);
            // Nested: the outer call's setting comes back when the inner one returns.
            super::serially(|| {
                super::serially(|| ());
                assert_eq!(super::min_split(10, 1), 10);
            });
            assert_eq!(super::min_split(10, 1), 1);
            // A panic inside it leaves the thread as it was.
            let caught = std::panic::catch_unwind(|| super::serially(|| panic!("inside")));
            assert!(caught.is_err());
            assert_eq!(super::min_split(10, 1), 1);
        });
    }
}
