//! The worker threads give the serial loop's answers, in order; the rows and
//! designs built on threads are the serial ones.

use crate::parallel::*;

#[test]
fn results_come_back_in_order() {
    for threads in [1, 2, 3, 8] {
        let out = map(50, threads, |i| i * i);
        assert_eq!(out, (0..50).map(|i| i * i).collect::<Vec<_>>());
    }
    assert!(map(0, 4, |i| i).is_empty());
}

#[test]
fn a_stop_ends_the_list_there_as_the_serial_loop() {
    for threads in [1, 2, 4] {
        let out = map_until(40, threads, |i| i, |&i| i % 7 == 6);
        assert_eq!(out, (0..7).collect::<Vec<_>>());
        let out = map_until(5, threads, |i| i, |_| false);
        assert_eq!(out, vec![0, 1, 2, 3, 4]);
    }
}

/// Threads the system refuses (none, some, all) leave their work to
/// the calling thread: the same results, in order.
#[test]
fn refused_threads_leave_their_work_here() {
    for refused in [1, 2, 3, 10] {
        REFUSE.with(|r| r.set(refused));
        let out = map(50, 4, |i| i * i);
        assert_eq!(out, (0..50).map(|i| i * i).collect::<Vec<_>>());
        REFUSE.with(|r| r.set(refused));
        let out = map_until(40, 4, |i| i, |&i| i % 7 == 6);
        assert_eq!(out, (0..7).collect::<Vec<_>>());
        REFUSE.with(|r| r.set(refused));
        let mut items: Vec<usize> = (0..30).collect();
        let r = for_runs_mut(&mut items, 4, |first, run| {
            for (k, v) in run.iter_mut().enumerate() {
                *v = 10 * (first + k) + usize::from(threads() == 1);
            }
            if first == 16 {
                return Err(first);
            }
            Ok(())
        });
        assert_eq!(r, Err(16), "{refused} refused");
        assert_eq!(items, (0..30).map(|i| 10 * i + 1).collect::<Vec<_>>());
    }
    REFUSE.with(|r| r.set(0));
}

#[test]
fn work_on_a_worker_is_serial() {
    let inner = map(4, 4, |_| threads());
    assert_eq!(inner, vec![1; 4]);
}

/// Every item once, the first error in item order, every item before
/// it done; with none, some or all threads refused.
#[test]
fn items_taken_in_turn() {
    for (threads, refused) in [(1, 0), (2, 0), (3, 0), (8, 0), (4, 2), (4, 10)] {
        let mut items = vec![0_usize; 200];
        REFUSE.with(|r| r.set(refused));
        let r = for_each_mut(&mut items, threads, |k, v| {
            *v += k + 1;
            Ok::<(), usize>(())
        });
        assert_eq!(r, Ok(()));
        assert_eq!(items, (1..=200).collect::<Vec<_>>(), "{threads} threads");
        REFUSE.with(|r| r.set(refused));
        let r = for_each_mut(&mut items, threads, |k, v| {
            if k % 50 == 37 {
                return Err(k);
            }
            *v = 0;
            Ok(())
        });
        assert_eq!(r, Err(37), "{threads} threads");
        assert!(items[..37].iter().all(|&v| v == 0));
        assert_eq!(items[37], 38);
    }
    REFUSE.with(|r| r.set(0));
}

#[test]
fn the_first_error_in_item_order() {
    for t in [1, 2, 5] {
        let mut v: Vec<u32> = (0..100).collect();
        let r = for_runs_mut(&mut v, t, |_, run| {
            for x in run.iter_mut() {
                if *x == 40 || *x == 90 {
                    return Err(*x);
                }
                *x += 1000;
            }
            Ok(())
        });
        assert_eq!(r, Err(40));
        assert_eq!(v[0], 1000);
    }
}
