//! An ordered sliding window over work items: worker threads take items in order and may run
//! ahead of the consumer by at most `window` items; the consumer receives the results strictly
//! in item order. Unlike fixed batches with a barrier, one slow item (a dense chunk) does not
//! leave the other threads idle, and the results held in memory stay bounded by the window.

use std::collections::BTreeMap;
use std::sync::{Condvar, Mutex};

struct State<T> {
    next_claim: usize,
    next_take: usize,
    ready: BTreeMap<usize, T>,
    stop: bool,
}

/// Runs `work(i)` for `i` in `range` on `workers` threads of `pool` and hands the results to
/// `sink(i, result)` on the calling thread in increasing `i`. A worker claims item `i` only
/// when `i < next item to sink + window`. If `sink` fails, no new item is started and the
/// error is returned once the running ones are done.
pub(crate) fn ordered<T: Send, E>(
    pool: &rayon::ThreadPool,
    workers: usize,
    window: usize,
    range: std::ops::Range<usize>,
    work: &(dyn Fn(usize) -> T + Sync),
    sink: &mut dyn FnMut(usize, T) -> Result<(), E>,
) -> Result<(), E> {
    assert!(workers > 0 && window > 0);
    let state = Mutex::new(State {
        next_claim: range.start,
        next_take: range.start,
        ready: BTreeMap::new(),
        stop: false,
    });
    let cv = Condvar::new();
    let lock = || state.lock().unwrap_or_else(|p| p.into_inner());
    let end = range.end;
    std::thread::scope(|scope| {
        for _ in 0..workers {
            scope.spawn(|| {
                pool.install(|| loop {
                    let i = {
                        let mut s = lock();
                        while !s.stop && s.next_claim < end && s.next_claim >= s.next_take + window
                        {
                            s = cv.wait(s).unwrap_or_else(|p| p.into_inner());
                        }
                        if s.stop || s.next_claim >= end {
                            return;
                        }
                        s.next_claim += 1;
                        s.next_claim - 1
                    };
                    let r = work(i);
                    lock().ready.insert(i, r);
                    cv.notify_all();
                })
            });
        }
        let mut result = Ok(());
        for i in range.clone() {
            let r = {
                let mut s = lock();
                loop {
                    if let Some(r) = s.ready.remove(&i) {
                        s.next_take = i + 1;
                        break r;
                    }
                    s = cv.wait(s).unwrap_or_else(|p| p.into_inner());
                }
            };
            cv.notify_all();
            if let Err(e) = sink(i, r) {
                result = Err(e);
                break;
            }
        }
        lock().stop = true;
        cv.notify_all();
        result
    })
}

#[cfg(test)]
mod tests {
    use super::*;
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
        );
        assert_eq!(r, Err("full disk"));
        assert!(started.load(Ordering::SeqCst) <= 10 + 1 + 2);
    }
}
