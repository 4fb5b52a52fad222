//! Whether the calling thread blocked since it last looked: how the receive thread tells a
//! sample that woke it from one it read on from its socket's backlog. A gap in time between two
//! samples cannot tell them apart on a loaded machine (a thread preempted while reading a backlog
//! sees gaps too); the thread's own count of the times it blocked can.

use std::cell::Cell;

thread_local! {
    static SETTLED: Cell<Option<i64>> = const { Cell::new(None) };
}

/// The calling thread's voluntary context switches so far: each time it blocked (waiting for its
/// socket, a timer, a lock, a sleep). Being preempted does not count. `None` where the system
/// does not count them per thread.
pub fn voluntary_switches() -> Option<i64> {
    #[cfg(target_os = "linux")]
    {
        let mut usage = std::mem::MaybeUninit::<libc::rusage>::zeroed();
        // SAFETY: getrusage fills the whole rusage it is given, and is checked before it is read
        if unsafe { libc::getrusage(libc::RUSAGE_THREAD, usage.as_mut_ptr()) } == 0 {
            return Some(unsafe { usage.assume_init() }.ru_nvcsw as i64);
        }
    }
    None
}

/// Whether the calling thread blocked since it last called `settle` (true the first time).
/// `None` where the system cannot tell.
pub fn blocked_since_settled() -> Option<bool> {
    let now = voluntary_switches()?;
    Some(SETTLED.with(|settled| settled.get() != Some(now)))
}

/// Remember the calling thread's count so far: what it did until now is not a block to come.
pub fn settle() {
    if let Some(now) = voluntary_switches() {
        SETTLED.with(|settled| settled.set(Some(now)));
    }
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn a_sleep_is_a_block_and_work_is_not() {
        settle();
        assert_eq!(blocked_since_settled(), Some(false));
        let mut x = 0u64;
        for i in 0..1_000_000u64 {
            x = x.wrapping_mul(31).wrapping_add(i);
        }
        std::hint::black_box(x);
        assert_eq!(blocked_since_settled(), Some(false));
        std::thread::sleep(Duration::from_millis(1));
        assert_eq!(blocked_since_settled(), Some(true));
        settle();
        assert_eq!(blocked_since_settled(), Some(false));
    }

    #[test]
    fn each_thread_counts_its_own() {
        settle();
        std::thread::spawn(|| std::thread::sleep(Duration::from_millis(1))).join().unwrap();
        // joining blocked this thread; a fresh thread has never settled
        assert_eq!(blocked_since_settled(), Some(true));
        std::thread::spawn(|| assert_eq!(blocked_since_settled(), Some(true))).join().unwrap();
    }
}
