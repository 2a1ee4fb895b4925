//! Work shared between the calling thread and the pool: the envs of a step are handed out one
//! at a time, from an atomic counter, to whichever thread asks next, and the calling thread asks
//! too instead of sleeping until the pool is done.
//!
//! Why: between two steps of a training loop the pool's threads fall asleep (the policy runs
//! meanwhile), and waking a sleeping thread costs tens of microseconds on a virtual machine. With
//! the pool doing all the work, every step paid for waking the workers and then for waking the
//! caller at the end. Here the caller starts on the first env at once, a worker that wakes late
//! simply takes fewer envs, and the caller wakes nobody but the workers. Which thread steps which
//! env never changes an env's results (envs share nothing), so they stay bitwise identical.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Instant;

/// How long the calling thread spins for the helpers' last rows before it sleeps: a little over
/// one env's agent step in the default config (10 physics steps of 9-10 us).
const SPIN: std::time::Duration = std::time::Duration::from_micros(150);

/// Items `0..len` handed out at most once each, from any thread.
pub(crate) struct Queue<T: Rows> {
    rows: T,
    next: AtomicUsize,
}

/// Something that yields disjoint mutable rows by index.
///
/// # Safety
/// `row(i)` must only touch data belonging to row `i`, so that rows of distinct indices may be
/// used at the same time from different threads.
pub(crate) unsafe trait Rows: Sync {
    /// What one row is.
    type Row<'r>
    where
        Self: 'r;
    /// Number of rows.
    fn len(&self) -> usize;
    /// Row `i`.
    ///
    /// # Safety
    /// `i < len()`, and row `i` is not taken twice while a taken one lives.
    unsafe fn row(&self, i: usize) -> Self::Row<'_>;
}

impl<T: Rows> Queue<T> {
    pub fn new(rows: T) -> Self {
        Queue {
            rows,
            next: AtomicUsize::new(0),
        }
    }

    /// The next row nobody has taken, or None when all are.
    pub fn pop(&self) -> Option<T::Row<'_>> {
        let i = self.next.fetch_add(1, Ordering::Relaxed);
        // Each index comes out of the counter once (it can only grow past the rows' length by
        // one per asking thread, which never wraps a usize), so row i is handed out once.
        // SAFETY: i < len(), and row i is handed out only here, once.
        (i < self.rows.len()).then(|| unsafe { self.rows.row(i) })
    }
}

/// Runs `take_one` (which takes the next row of a [`Queue`], works on it and says whether there
/// was one) until no row is left, on `helpers` jobs of `pool` and, if `caller_works`, on the
/// calling thread too; the calling thread then waits for the helpers. It asks `interrupted()`
/// between its rows and while it waits, at most every `interval` apart, and sets `stop` once it
/// says so (the work reads `stop`). Returns when every helper has finished; a panic in a helper
/// or in the calling thread's own rows is resumed after that.
pub(crate) fn run_shared(
    pool: &rayon::ThreadPool,
    helpers: usize,
    caller_works: bool,
    take_one: &(dyn Fn() -> bool + Sync),
    stop: &AtomicBool,
    interval: std::time::Duration,
    interrupted: &mut dyn FnMut() -> bool,
) {
    /// Counts a helper out and wakes the caller, also when the helper panics.
    struct Done<'a> {
        outstanding: &'a AtomicUsize,
        caller: std::thread::Thread,
    }
    impl Drop for Done<'_> {
        fn drop(&mut self) {
            self.outstanding.fetch_sub(1, Ordering::Release);
            self.caller.unpark();
        }
    }
    let outstanding = AtomicUsize::new(helpers);
    let caller = std::thread::current();
    let mut last = Instant::now();
    let mut watch = |last: &mut Instant| {
        if last.elapsed() >= interval {
            *last = Instant::now();
            if !stop.load(Ordering::Relaxed) && interrupted() {
                stop.store(true, Ordering::Relaxed);
            }
        }
    };
    pool.in_place_scope(|scope| {
        for _ in 0..helpers {
            let (outstanding, caller) = (&outstanding, caller.clone());
            scope.spawn(move |_| {
                let _done = Done {
                    outstanding,
                    caller,
                };
                while take_one() {}
            });
        }
        // The caller's share. A panic here unwinds out of the scope, which first waits for the
        // helpers (they finish the remaining rows).
        while caller_works && take_one() {
            watch(&mut last);
        }
        // After the caller's share the helpers are at most one row from done: spin that long
        // before sleeping (a wake-up costs about as much), then sleep until they count
        // themselves out. A caller that only watches sleeps at once (the rows are long).
        if caller_works {
            let spin_until = Instant::now() + SPIN;
            while outstanding.load(Ordering::Acquire) > 0 && Instant::now() < spin_until {
                std::hint::spin_loop();
            }
        }
        while outstanding.load(Ordering::Acquire) > 0 {
            std::thread::park_timeout(interval);
            watch(&mut last);
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::marker::PhantomData;
    use std::time::Duration;

    /// Rows of a slice of counters.
    struct Counters<'a> {
        ptr: *mut u32,
        len: usize,
        _b: PhantomData<&'a mut [u32]>,
    }
    unsafe impl Sync for Counters<'_> {}
    unsafe impl<'a> Rows for Counters<'a> {
        type Row<'r>
            = &'r mut u32
        where
            Self: 'r;
        fn len(&self) -> usize {
            self.len
        }
        unsafe fn row(&self, i: usize) -> &mut u32 {
            &mut *self.ptr.add(i)
        }
    }

    fn counters(v: &mut [u32]) -> Counters<'_> {
        Counters {
            ptr: v.as_mut_ptr(),
            len: v.len(),
            _b: PhantomData,
        }
    }

    #[test]
    fn every_row_runs_exactly_once_whatever_the_helpers() {
        for threads in [1, 2, 4] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            for helpers in 0..threads {
                for len in [0, 1, 2, 7, 64] {
                    let mut v = vec![0u32; len];
                    let queue = Queue::new(counters(&mut v));
                    let stop = AtomicBool::new(false);
                    let take_one = || queue.pop().map(|c| *c += 1).is_some();
                    // The caller works when nobody else does, and otherwise for odd lengths
                    // only: both modes are covered.
                    run_shared(
                        &pool,
                        helpers,
                        helpers == 0 || len % 2 == 1,
                        &take_one,
                        &stop,
                        Duration::from_millis(10),
                        &mut || false,
                    );
                    assert!(
                        v.iter().all(|&c| c == 1),
                        "{threads} {helpers} {len}: {v:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn the_caller_watches_while_a_helper_runs_long_and_a_helper_panic_is_resumed() {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let mut v = vec![0u32; 2];
        let queue = Queue::new(counters(&mut v));
        let stop = AtomicBool::new(false);
        let helper_started = AtomicBool::new(false);
        let mut asked = 0;
        // The caller's row waits until the helper holds the other; the helper's runs 60 ms
        // and panics, while the caller waits and asks every 5 ms.
        let job = |c: &mut u32| {
            *c += 1;
            if rayon::current_thread_index().is_some() {
                helper_started.store(true, Ordering::SeqCst);
                std::thread::sleep(Duration::from_millis(60));
                panic!("late bug");
            }
            while !helper_started.load(Ordering::SeqCst) {
                std::hint::spin_loop();
            }
        };
        let take_one = || queue.pop().map(job).is_some();
        let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            run_shared(
                &pool,
                1,
                true,
                &take_one,
                &stop,
                Duration::from_millis(5),
                &mut || {
                    asked += 1;
                    asked >= 3
                },
            )
        }));
        let message = r.expect_err("the helper's panic is resumed");
        assert_eq!(message.downcast_ref::<&str>(), Some(&"late bug"));
        assert!(
            stop.load(Ordering::SeqCst),
            "asked {asked} times while waiting"
        );
        assert_eq!(v, [1, 1]);
    }
}
