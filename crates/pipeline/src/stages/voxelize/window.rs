//! An ordered sliding window over work items: worker threads take items in order and may run
//! ahead of the consumer by at most `window` items; the consumer receives the results strictly
//! in item order. Unlike fixed batches with a barrier, one slow item (a dense chunk) does not
//! leave the other threads idle, and the results held in memory stay bounded by the window.
//!
//! Failure handling: a panic in `work(i)` is caught on the worker and reaches the consumer as
//! an error for item `i` (through `on_panic`), in its place in the order, so the consumer never
//! waits for a result that will not come. A panic in the consumer's `sink` stops the workers
//! before it propagates. A poisoned state lock (a panic while holding it, which this file's own
//! code never does) is reported as an error, not silently used.

use std::collections::BTreeMap;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::{Condvar, Mutex, MutexGuard};

struct State<T> {
    next_claim: usize,
    next_take: usize,
    /// Finished items: the result, or the panic message of `work(i)`.
    ready: BTreeMap<usize, Result<T, String>>,
    stop: bool,
    /// Workers that have not exited yet.
    alive: usize,
}

/// The text of a panic payload (`panic!` with a literal or a formatted message).
fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        s.to_string()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "a panic without a message".to_string()
    }
}

const POISONED: &str = "the work window's state lock was poisoned by a panic";

/// Sets `stop` and wakes everyone when dropped, so workers end even if the consumer unwinds.
struct StopOnDrop<'a, T> {
    state: &'a Mutex<State<T>>,
    cv: &'a Condvar,
}

impl<T> Drop for StopOnDrop<'_, T> {
    fn drop(&mut self) {
        // Only a flag is written here; a poisoned lock still holds a valid `bool`.
        self.state.lock().unwrap_or_else(|p| p.into_inner()).stop = true;
        self.cv.notify_all();
    }
}

/// Counts a worker out when it exits, however it exits, and wakes the consumer.
struct AliveGuard<'a, T> {
    state: &'a Mutex<State<T>>,
    cv: &'a Condvar,
}

impl<T> Drop for AliveGuard<'_, T> {
    fn drop(&mut self) {
        // Only a counter is written here; a poisoned lock still holds a valid `usize`.
        self.state.lock().unwrap_or_else(|p| p.into_inner()).alive -= 1;
        self.cv.notify_all();
    }
}

/// Runs `work(i)` for `i` in `range` on `workers` threads of `pool` and hands the results to
/// `sink(i, result)` on the calling thread in increasing `i`. A worker claims item `i` only
/// when `i < next item to sink + window`. If `sink` fails, no new item is started and the
/// error is returned once the running ones are done. If `work(i)` panics, the error
/// `on_panic(i, message)` is returned in its place (after items before `i` were sunk) and no
/// new item is started.
pub(crate) fn ordered<T: Send, E>(
    pool: &rayon::ThreadPool,
    workers: usize,
    window: usize,
    range: std::ops::Range<usize>,
    work: &(dyn Fn(usize) -> T + Sync),
    sink: &mut dyn FnMut(usize, T) -> Result<(), E>,
    on_panic: &dyn Fn(usize, &str) -> E,
) -> Result<(), E> {
    assert!(workers > 0 && window > 0);
    let state = Mutex::new(State {
        next_claim: range.start,
        next_take: range.start,
        ready: BTreeMap::new(),
        stop: false,
        alive: workers,
    });
    let cv = Condvar::new();
    let lock = || -> Result<MutexGuard<'_, State<T>>, ()> { state.lock().map_err(|_| ()) };
    let end = range.end;
    std::thread::scope(|scope| {
        // first, so that workers already started end however the consumer leaves
        let _stop = StopOnDrop {
            state: &state,
            cv: &cv,
        };
        for _ in 0..workers {
            scope.spawn(|| {
                let _alive = AliveGuard {
                    state: &state,
                    cv: &cv,
                };
                pool.install(|| loop {
                    let i = {
                        let Ok(mut s) = lock() else { return };
                        while !s.stop && s.next_claim < end && s.next_claim >= s.next_take + window
                        {
                            let Ok(g) = cv.wait(s) else { return };
                            s = g;
                        }
                        if s.stop || s.next_claim >= end {
                            return;
                        }
                        s.next_claim += 1;
                        s.next_claim - 1
                    };
                    let r = catch_unwind(AssertUnwindSafe(|| work(i)))
                        .map_err(|p| panic_message(p.as_ref()));
                    let failed = r.is_err();
                    let Ok(mut s) = lock() else { return };
                    s.ready.insert(i, r);
                    // After a panic no new item is started; the consumer reports it.
                    s.stop |= failed;
                    drop(s);
                    cv.notify_all();
                })
            });
        }
        for i in range.clone() {
            let r = {
                let Ok(mut s) = lock() else {
                    return Err(on_panic(i, POISONED));
                };
                loop {
                    if let Some(r) = s.ready.remove(&i) {
                        s.next_take = i + 1;
                        break r;
                    }
                    if s.alive == 0 {
                        // Every worker is gone and item i never arrived (a worker left on a
                        // poisoned lock): an error in its place rather than a wait forever.
                        return Err(on_panic(i, "the workers stopped before this item arrived"));
                    }
                    s = match cv.wait(s) {
                        Ok(g) => g,
                        Err(_) => return Err(on_panic(i, POISONED)),
                    };
                }
            };
            cv.notify_all();
            match r {
                Ok(r) => sink(i, r)?,
                Err(message) => return Err(on_panic(i, &message)),
            }
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::panic::AssertUnwindSafe;
    use std::sync::atomic::{AtomicUsize, Ordering};

    #[test]
    fn results_arrive_in_order_and_the_window_bounds_the_lead() {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(3)
            .build()
            .unwrap();
        let taken = AtomicUsize::new(5);
        let max_lead = AtomicUsize::new(0);
        let mut got = Vec::new();
        ordered::<usize, ()>(
            &pool,
            3,
            4,
            5..200,
            &|i| {
                // uneven work: every 7th item is slow
                if i % 7 == 0 {
                    std::thread::sleep(std::time::Duration::from_millis(3));
                }
                let lead = i - taken.load(Ordering::SeqCst).min(i);
                max_lead.fetch_max(lead, Ordering::SeqCst);
                i * 2
            },
            &mut |i, r| {
                got.push((i, r));
                taken.store(i + 1, Ordering::SeqCst);
                Ok(())
            },
            &|i, m| panic!("item {i} panicked: {m}"),
        )
        .unwrap();
        assert_eq!(got, (5..200).map(|i| (i, i * 2)).collect::<Vec<_>>());
        assert!(
            max_lead.load(Ordering::SeqCst) <= 4 + 1,
            "ran ahead of the window"
        );
    }

    #[test]
    fn a_failing_sink_stops_the_work() {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        let started = AtomicUsize::new(0);
        let r = ordered(
            &pool,
            2,
            2,
            0..1000,
            &|i| {
                started.fetch_add(1, Ordering::SeqCst);
                i
            },
            &mut |i, _| if i == 10 { Err("full disk") } else { Ok(()) },
            &|_, _| "panic",
        );
        assert_eq!(r, Err("full disk"));
        assert!(started.load(Ordering::SeqCst) <= 10 + 1 + 2);
    }

    /// Runs `f` on its own thread and fails the test if it has not finished within `secs`
    /// (a hang becomes a failure, not a stuck test run).
    fn within<R: Send + 'static>(
        secs: u64,
        f: impl FnOnce() -> R + Send + 'static,
    ) -> std::thread::Result<R> {
        let (tx, rx) = std::sync::mpsc::channel();
        let h = std::thread::spawn(move || {
            let r = std::panic::catch_unwind(AssertUnwindSafe(f));
            let _ = tx.send(());
            r
        });
        rx.recv_timeout(std::time::Duration::from_secs(secs))
            .expect("hung: the window did not return");
        h.join().unwrap()
    }

    #[test]
    fn a_panicking_item_is_an_error_naming_it_not_a_hang() {
        let got = within(30, || {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(3)
                .build()
                .unwrap();
            let mut got = Vec::new();
            let r = ordered::<usize, String>(
                &pool,
                3,
                4,
                0..200,
                &|i| {
                    if i == 37 {
                        panic!("boom at {i}");
                    }
                    i
                },
                &mut |i, _| {
                    got.push(i);
                    Ok(())
                },
                &|i, m| format!("item {i}: {m}"),
            );
            (r, got)
        })
        .unwrap();
        assert_eq!(got.0, Err("item 37: boom at 37".to_string()));
        assert_eq!(got.1, (0..37).collect::<Vec<_>>());
    }

    #[test]
    fn a_panicking_sink_stops_the_workers_and_propagates() {
        let r = within(30, || {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(2)
                .build()
                .unwrap();
            ordered::<usize, ()>(
                &pool,
                2,
                2,
                0..1000,
                &|i| i,
                &mut |i, _| {
                    assert!(i != 5, "sink fails at 5");
                    Ok(())
                },
                &|_, _| (),
            )
        });
        let payload = r.expect_err("the sink's panic propagates");
        assert_eq!(panic_message(payload.as_ref()), "sink fails at 5");
    }

    #[test]
    fn every_item_panicking_is_still_one_error_for_the_first() {
        let r = within(30, || {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(4)
                .build()
                .unwrap();
            ordered::<usize, String>(
                &pool,
                4,
                3,
                10..50,
                &|i| panic!("no {i}"),
                &mut |_, _| Ok(()),
                &|i, m| format!("item {i}: {m}"),
            )
        })
        .unwrap();
        assert_eq!(r, Err("item 10: no 10".to_string()));
    }
}
