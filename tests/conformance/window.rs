//! The candidate window (`CandidateHits`) must not depend on the order in
//! which hits are offered — neither its contents nor its overflow flag.

use splatray::accel::{Candidate, CandidateHits, MAX_CANDIDATES};

fn hit(id: u32, t: f32) -> Candidate {
    Candidate {
        id,
        t,
        u: 0.0,
        v: 0.0,
    }
}

/// Regression: the window used to set `overflowed` as soon as it was full
/// and one more hit came, even when a later, nearer hit moved the window so
/// that the dropped hits were no longer in it. Offered nearest first, the
/// same hits never overflowed: the flag depended on the offer order.
#[test]
fn overflow_flag_does_not_depend_on_offer_order() {
    let xi = 0.1;
    // 33 hits in [1.0, 1.033] (more than fit), then one at 0.5 whose window
    // [0.5, 0.6] excludes them all.
    let far: Vec<Candidate> = (0..=MAX_CANDIDATES as u32)
        .map(|i| hit(i + 1, 1.0 + i as f32 * 1e-3))
        .collect();
    let near = hit(100, 0.5);

    let mut late = CandidateHits::new(xi);
    for c in &far {
        late.offer(*c);
    }
    assert!(late.overflowed(), "33 hits within xi overflow a 32-window");
    late.offer(near);

    let mut early = CandidateHits::new(xi);
    early.offer(near);
    for c in &far {
        early.offer(*c);
    }
    assert_eq!(late.as_slice(), early.as_slice());
    assert_eq!(late.as_slice(), &[near]);
    assert!(
        !late.overflowed(),
        "only one hit is in the final window, yet overflowed is set"
    );
    assert!(!early.overflowed());
}

#[test]
fn overflow_is_kept_when_a_dropped_hit_stays_in_the_window() {
    let mut w = CandidateHits::new(1.0);
    // 40 hits in reverse order, all within xi of each other.
    for i in (0..40u32).rev() {
        w.offer(hit(i, 1.0 + i as f32 * 1e-3));
    }
    assert!(w.overflowed());
    assert_eq!(w.as_slice().len(), MAX_CANDIDATES);
    let ids: Vec<u32> = w.as_slice().iter().map(|c| c.id).collect();
    assert_eq!(ids, (0..MAX_CANDIDATES as u32).collect::<Vec<_>>());
    w.clear();
    assert!(!w.overflowed() && w.is_empty());
}

#[test]
fn duplicate_ids_are_kept_once() {
    let mut w = CandidateHits::new(1.0);
    w.offer(hit(7, 2.0));
    w.offer(hit(3, 2.0));
    w.offer(hit(7, 2.0));
    let ids: Vec<u32> = w.as_slice().iter().map(|c| c.id).collect();
    assert_eq!(ids, vec![3, 7]);
}
