//! The decode-ahead thread: after a request for frame `a`, it fills the cache with the frames
//! after `a` (so playing forward never waits) and then the few before it (so a step back is a
//! hit). It reads one frame at a time and waits whenever a request is decoding, so a request
//! waits at most for one frame's read. It reads on from the requests' decoder where that is
//! positioned for it, else from a decoder of its own, which a new request kills (a restart
//! costs a seek that the request should not have to wait behind).

use super::reader::{Shared, lock};
use super::stream::Stream;
use std::sync::Arc;

/// What the thread does until the reader is dropped.
pub(crate) fn run(shared: &Arc<Shared>) {
    let mut own: Option<Stream> = None;
    let mut generation = 0;
    let mut reads = 0usize;
    while let Some((anchor, now)) = wait_for_work(shared) {
        if now != generation {
            generation = now;
            reads = 0;
        }
        let (ahead, back) = shared.reach();
        // A bound on work per anchor: if another thread's requests keep evicting what this
        // one fills, it stops rather than decode in circles.
        let budget = 4 * (ahead + back + 1);
        let want = next_wanted(shared, anchor, ahead, back).filter(|_| reads < budget);
        let Some(want) = want else {
            settle(shared, &mut own, anchor + ahead + 1);
            rest(shared, generation);
            continue;
        };
        reads += 1;
        if let Err(e) = step(shared, want, &mut own, generation) {
            // Killed by a request is no news; anything else: give this anchor up, the request
            // for the frame will meet the error itself.
            if lock(&shared.plan).generation == generation {
                log::debug!("decode-ahead stopped: {e}");
                rest(shared, generation);
            }
        }
    }
    *lock(&shared.helper) = None;
}

/// The anchor and the generation to work for, once there is work and no request is decoding;
/// `None` when the reader is dropped.
fn wait_for_work(shared: &Shared) -> Option<(usize, u64)> {
    let mut plan = lock(&shared.plan);
    loop {
        if plan.shutdown {
            return None;
        }
        if plan.requests == 0
            && plan.rested != Some(plan.generation)
            && let Some(anchor) = plan.anchor
        {
            return Some((anchor, plan.generation));
        }
        plan = shared
            .wake
            .wait(plan)
            .unwrap_or_else(|poisoned| poisoned.into_inner());
    }
}

/// Marks `generation` done, unless a request has moved the anchor since.
fn rest(shared: &Shared, generation: u64) {
    let mut plan = lock(&shared.plan);
    if plan.generation == generation {
        plan.rested = Some(generation);
    }
}

/// The first frame missing after the anchor, else the first missing before it.
fn next_wanted(shared: &Shared, anchor: usize, ahead: usize, back: usize) -> Option<usize> {
    let count = shared.source.info.frame_count;
    let cache = lock(&shared.cache);
    let after = (anchor + 1..=anchor + ahead).take_while(|&i| i < count);
    let before = anchor.saturating_sub(back)..anchor;
    after.chain(before).find(|&i| !cache.contains(i))
}

/// Reads one frame towards `want`: from the requests' decoder if it can reach it, else from
/// this thread's own (started at `want` if it cannot reach it either).
fn step(
    shared: &Shared,
    want: usize,
    own: &mut Option<Stream>,
    generation: u64,
) -> Result<(), super::VideoError> {
    {
        let mut main = lock(&shared.main);
        if let Some(stream) = main.as_mut()
            && shared.can_reach(stream, want)
        {
            let read = shared.read_into_cache(stream);
            if read.is_err() {
                *main = None;
            }
            return read;
        }
    }
    let stream = match own.take() {
        Some(s) if shared.can_reach(&s, want) => s,
        old => {
            drop(old);
            let fresh = shared.source.spawn(want)?;
            *lock(&shared.helper) = Some(fresh.kill_switch());
            // A request that came while it started has not seen its kill switch.
            if lock(&shared.plan).generation != generation {
                *lock(&shared.helper) = None;
                return Ok(());
            }
            fresh
        }
    };
    let stream = own.insert(stream);
    let read = shared.read_into_cache(stream);
    if read.is_err() {
        *own = None;
        *lock(&shared.helper) = None;
    }
    read
}

/// Done for now: if this thread's decoder is positioned for the frames after the filled ones
/// (`next`) and the requests' decoder is not, it becomes the requests' decoder; else it stops.
fn settle(shared: &Shared, own: &mut Option<Stream>, next: usize) {
    let Some(stream) = own.take() else { return };
    *lock(&shared.helper) = None;
    if next >= shared.source.info.frame_count || !shared.can_reach(&stream, next) {
        return;
    }
    let mut main = lock(&shared.main);
    if !main.as_ref().is_some_and(|m| shared.can_reach(m, next)) {
        *main = Some(stream);
    }
}
